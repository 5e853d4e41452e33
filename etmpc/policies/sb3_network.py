"""A Stable-Baselines3 policy's network, read from its zip as data and evaluated in numpy (for
:mod:`etmpc.policies.sb3`): the zip's ``data`` entry as JSON, the policy class's pickle listed by
``pickletools`` and never run, the weights through torch's weights-only reader, checked against
the architecture; :class:`Network` evaluates the tanh layers and the action logits, and decides a
near tie again with exact sums. A policy's model has two actions (keep, recompute) or, on a task with
compute levels, three (keep, one SQP iteration, a full solve)."""

from __future__ import annotations

import base64
import io
import json
import math
import pickletools
import warnings
import zipfile
from pathlib import Path

import numpy as np

from etmpc.common.errors import EtmpcError
from etmpc.common.interrupts import described, genuine
from etmpc.common.numerics import matvec

TOLERANCE = 1e-6  # logits closer than this are decided again, exactly (see Network)
POLICY_CLASS = "stable_baselines3.common.policies.ActorCriticPolicy"  # what PPO's "MlpPolicy" is
BOX, DISCRETE = "<class 'gymnasium.spaces.box.Box'>", "<class 'gymnasium.spaces.discrete.Discrete'>"
DEFAULT_NET_ARCH = [64, 64]  # ActorCriticPolicy's policy layers when policy_kwargs has no net_arch
ALGORITHMS = ("a2c", "ddpg", "dqn", "ppo", "sac", "td3")  # Stable-Baselines3's
MEANINGS = {2: "keep, recompute", 3: "keep, one SQP iteration, a full solve"}  # a policy's actions, by their number
MAX_ENTRY = 64 << 20  # bytes of 'data' or 'policy.pth': far above a policy's network, far below a zip bomb

_STRINGS = {"STRING", "BINSTRING", "SHORT_BINSTRING", "UNICODE", "BINUNICODE", "SHORT_BINUNICODE", "BINUNICODE8"}
_MEMO = {"MEMOIZE", "PUT", "BINPUT", "LONG_BINPUT"}
_REFERENCE = _STRINGS | _MEMO | {"PROTO", "FRAME", "GLOBAL", "STACK_GLOBAL", "STOP"}  # a class, and nothing done


def metadata_path(model: Path) -> Path:
    """The description etmpc writes beside a model (``MODEL.json``)."""
    return Path(model).with_suffix(".json")


class Network:
    """The actor of a PPO ``MlpPolicy``: ``hidden`` layers ``h = tanh(W h + b)``, then the action logits
    ``W h + b`` (``head``, one row per action); the deterministic action is the largest logit's, the
    lowest such index on a tie (SB3's Categorical mode: torch's argmax of the probabilities).

    The weights are float32 values held in float64, and so is the observation: the first layer's
    products are exact. The logits are computed in float64 with numpy (BLAS, SIMD ``tanh``); when the
    largest is within :data:`TOLERANCE` of the next (far above any difference of rounding between
    kernels), the decision is made again as :mod:`etmpc.common.numerics` makes every decision: each
    pre-activation the exactly rounded sum of its IEEE-rounded products and its bias
    (:func:`~etmpc.common.numerics.matvec`), then ``math.tanh`` (the C library's scalar routine), and an
    action beats a lower one only if its logit is strictly larger (a tie is the lower action, as torch's
    argmax gives). So no decision hinges on the kernel, the vector width or the threads the CPU selects.
    With two actions this is action 1 exactly when ``logits[1] - logits[0]`` is positive.

    SB3 computes the same network in float32 and takes the argmax of the softmax: the two agree
    unless the logits are within float32 noise of each other; ``tests/policies/test_sb3_safe.py`` compares them
    at every decision of the shipped models on test-set episodes, ``tests/policies/test_sb3_levels.py``
    a three-action network on random observations and near ties."""

    def __init__(self, hidden: list[tuple[np.ndarray, np.ndarray]], head: tuple[np.ndarray, np.ndarray]):
        self.hidden, self.head = hidden, head

    @property
    def actions(self) -> int:
        """How many actions the network chooses among (its logits)."""
        return self.head[0].shape[0]

    def logits(self, x: np.ndarray) -> np.ndarray:
        h = np.asarray(x, dtype=np.float64)
        for weight, bias in self.hidden:
            h = np.tanh(weight @ h + bias)
        return self.head[0] @ h + self.head[1]

    def exact_logits(self, x: np.ndarray) -> np.ndarray:
        h = np.asarray(x, dtype=np.float64)
        for weight, bias in self.hidden:
            h = np.array([math.tanh(v) for v in _exact_layer(weight, bias, h)])
        return _exact_layer(*self.head, h)

    def action(self, x: np.ndarray) -> int:
        """The action (0 keep, 1 recompute; with three, 0 keep, 1 one SQP iteration, 2 a full solve) for
        the normalised observation ``x`` (float32), see the class's docstring."""
        logits = self.logits(x)
        best = int(np.argmax(logits))  # the first largest (a nan's, if any: its margin is nan)
        margin = logits[best] - np.max(np.delete(logits, best))
        if margin > TOLERANCE:  # a nan margin (a nan observation) goes on too: the exact sums give 0
            return best
        return first_largest(self.exact_logits(x))


def first_largest(values) -> int:
    """The index of the largest of ``values``, the lowest on a tie: each beats the best so far only if
    strictly larger (so a nan never wins, and with nans at 0 the answer is 0)."""
    best = 0
    for i in range(1, len(values)):
        if values[i] > values[best]:
            best = i
    return best


def _exact_layer(weight: np.ndarray, bias: np.ndarray, h: np.ndarray) -> np.ndarray:
    return matvec(np.column_stack([weight, bias]), np.append(h, 1.0))


def _short(value) -> str:
    text = " ".join(repr(value).split())
    return text if len(text) <= 80 else text[:80] + "…"


def pickled_globals(encoded) -> tuple[list[str], bool]:
    """The globals (``module.name``) that the base64 pickle ``encoded`` names, and whether it does
    nothing but name them (no call, no object built). It is parsed (:func:`pickletools.genops`), never
    run; a global whose name comes from the pickle's memo is ``"?"``. ``ValueError`` if it is no pickle."""
    if not isinstance(encoded, str):
        raise ValueError("not base64 text")
    found: list[str] = []
    only_references = True
    recent: list[str | None] = []  # what was pushed last: a STACK_GLOBAL's module and name are strings (None: not one)
    for op, arg, _ in pickletools.genops(base64.b64decode(encoded, validate=True)):
        only_references = only_references and op.name in _REFERENCE
        if op.name == "GLOBAL":
            found.append(str(arg).replace(" ", "."))
        elif op.name == "STACK_GLOBAL":
            names = recent[-2:]
            found.append(".".join(map(str, names)) if len(names) == 2 and None not in names else "?")
        if op.name in _STRINGS:
            recent.append(arg)
        elif op.name not in _MEMO:
            recent.append(None)
    return found, only_references


def _entries(path: Path) -> tuple[bytes, bytes]:
    """The zip's ``data`` and ``policy.pth``, read as bytes."""
    not_a_model = f"sb3:{path} is not a Stable-Baselines3 model"
    try:
        archive = zipfile.ZipFile(path)
    except BaseException as exc:  # BadZipFile mostly; a foreign file can fail in other ways
        if genuine(exc):
            raise
        raise EtmpcError(f"{not_a_model} (not a readable zip file: {described(exc)})") from None
    with archive:
        members = {info.filename: info for info in archive.infolist()}
        if not {"data", "policy.pth"} <= members.keys():
            raise EtmpcError(f"{not_a_model} (its zip has no 'data' and 'policy.pth'; save one with model.save(PATH))")
        for name in ("data", "policy.pth"):
            if members[name].file_size > MAX_ENTRY:
                raise EtmpcError(
                    f"{not_a_model} (its {name} holds {members[name].file_size} bytes, more than {MAX_ENTRY >> 20} MiB)"
                )
        try:
            return archive.read("data"), archive.read("policy.pth")
        except BaseException as exc:  # a damaged member: bad CRC, zlib's error, an unknown compression
            if genuine(exc):
                raise
            raise EtmpcError(f"{not_a_model} (its zip cannot be read: {described(exc)})") from None


def _fields(path: Path, data: bytes) -> dict:
    """The zip's ``data``, read as JSON (a ``:serialized:`` value stays the base64 text it is)."""
    try:
        fields = json.loads(data)
    except (ValueError, RecursionError) as exc:
        raise EtmpcError(f"sb3:{path} is not a Stable-Baselines3 model (its data is not JSON: {described(exc)})") from None
    if not isinstance(fields, dict):
        raise EtmpcError(f"sb3:{path} is not a Stable-Baselines3 model (its data is not a JSON object)")
    return fields


def _architecture(path: Path, data: bytes, size: int, actions: int = 2, task: str | None = None) -> list[int]:
    """The widths of the policy's hidden layers, from the zip's ``data`` read as JSON, if it is PPO's
    ``MlpPolicy`` on ``size`` observations and ``actions`` actions (``task``'s, named in the refusal);
    else :class:`EtmpcError`."""
    fields = _fields(path, data)
    policy_class = fields.get("policy_class")
    try:
        named, only = pickled_globals(policy_class.get(":serialized:") if isinstance(policy_class, dict) else None)
        what = (", ".join(named) or "none") if only else f"a pickle that calls {', '.join(named) or 'nothing'}"
    except Exception:  # pickletools' errors on a damaged pickle are of several kinds, all of a parser
        named, only, what = [], False, "an unreadable pickle" if isinstance(policy_class, dict) else "none given"
    if named != [POLICY_CLASS] or not only:
        raise EtmpcError(
            f"sb3:{path} needs a policy class etmpc does not read ({what}); etmpc reads only PPO's "
            f"MlpPolicy ({POLICY_CLASS}) and runs no pickled code"
        )
    spaces = {"observation": fields.get("observation_space"), "action": fields.get("action_space")}
    for (kind, space), wanted in zip(spaces.items(), (BOX, DISCRETE)):
        if not isinstance(space, dict) or space.get(":type:") != wanted:
            found = space.get(":type:") if isinstance(space, dict) else space
            raise EtmpcError(
                f"sb3:{path} needs an {kind} space of type {_short(found)}; etmpc reads a Box of "
                "observations and a Discrete of actions"
            )
    observation, action = spaces["observation"], spaces["action"]
    assert isinstance(observation, dict) and isinstance(action, dict)  # each refused above if not
    shape = observation.get("_shape")
    found = action.get("n")
    if shape != [size] or type(shape[0]) is not int or found != str(actions) or action.get("start", "0") != "0":
        shape = tuple(shape) if isinstance(shape, list) else shape
        raise EtmpcError(
            f"sb3:{path} takes observations of shape {_short(shape)} and {_short(found)} actions; the trigger "
            f"environment has ({size},) and {actions} ({MEANINGS.get(actions, 'its actions')})" + (f" on {task}" if task else "")
        )
    return _net_arch(path, fields.get("policy_kwargs", {}))


def _net_arch(path: Path, kwargs) -> list[int]:
    """The policy's hidden widths from ``policy_kwargs``, a plain JSON object with at most ``net_arch``."""
    if isinstance(kwargs, dict) and ":serialized:" in kwargs:
        keys = ", ".join(k for k in kwargs if not k.startswith(":")) or "no keys"
        try:
            named = ", ".join(pickled_globals(kwargs[":serialized:"])[0]) or "nothing"
        except Exception:
            named = "an unreadable pickle"
        raise EtmpcError(
            f"sb3:{path} needs policy_kwargs that only unpickling reads ({keys}; naming {named}); etmpc reads net_arch alone"
        )
    if not isinstance(kwargs, dict) or set(kwargs) - {"net_arch"}:
        extra = ", ".join(sorted(set(kwargs) - {"net_arch"})) if isinstance(kwargs, dict) else _short(kwargs)
        raise EtmpcError(f"sb3:{path} needs policy_kwargs etmpc does not read ({extra}); it reads net_arch alone")
    arch = kwargs.get("net_arch")
    arch = DEFAULT_NET_ARCH if arch is None else arch
    lists = [arch.get("pi", []), arch.get("vf", [])] if isinstance(arch, dict) and set(arch) <= {"pi", "vf"} else [arch]
    if not all(isinstance(w, list) and all(type(n) is int and n > 0 for n in w) for w in lists):
        raise EtmpcError(
            f"sb3:{path} needs net_arch {_short(arch)}; etmpc reads a list of layer widths or a dict of 'pi' and 'vf' lists"
        )
    return lists[0]


def _state_dict(path: Path, blob: bytes) -> dict:
    """``policy.pth`` through torch's weights-only reader (its restricted unpickler: tensors and plain
    containers, no other global), on the CPU."""
    try:
        import torch
    except ImportError:
        raise EtmpcError(f"sb3:{path} needs PyTorch to read its weights: pip install 'etmpc[rl]'") from None
    try:
        with warnings.catch_warnings():  # an unusual pickle protocol warns; the reader decides
            warnings.simplefilter("ignore")
            state = torch.load(io.BytesIO(blob), map_location="cpu", weights_only=True)
    except BaseException as exc:
        if genuine(exc):
            raise
        lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
        detail = next(
            (line for line in lines[1:] if not line.startswith(("Please file", "Check the documentation"))), described(exc)
        )
        raise EtmpcError(
            f"sb3:{path}: its policy.pth is not plain weights, torch's weights-only reader refuses it ({detail[:200]})"
        ) from None
    if not (isinstance(state, dict) and all(isinstance(k, str) and isinstance(v, torch.Tensor) for k, v in state.items())):
        raise EtmpcError(f"sb3:{path}: its policy.pth is not a state dict of tensors")
    return state


def _network(path: Path, state: dict, widths: list[int], size: int, actions: int = 2) -> Network:
    """The numpy network of ``state`` (a state dict), checked against the architecture: the policy's
    layers and the action layer with exactly the shapes it gives, float32 and finite; besides them only
    the value function's weights (not needed)."""
    import torch

    shapes: dict[str, tuple[int, ...]] = {}
    inputs = size
    for i, width in enumerate(widths):
        layer = f"mlp_extractor.policy_net.{2 * i}"  # the Linear before the i-th Tanh
        shapes |= {f"{layer}.weight": (width, inputs), f"{layer}.bias": (width,)}
        inputs = width
    shapes |= {"action_net.weight": (actions, inputs), "action_net.bias": (actions,)}
    fits = f"sb3:{path}: its policy.pth does not fit its architecture ({size} inputs, tanh layers {widths}, {actions} actions)"
    missing = [k for k in shapes if k not in state]
    if missing:
        raise EtmpcError(f"{fits}: it has no {missing[0]}")
    extra = [k for k in state if k not in shapes and not k.startswith(("mlp_extractor.value_net.", "value_net."))]
    if extra:
        raise EtmpcError(f"{fits}: it has {_short(extra[0])}, which the architecture has not")
    for key, shape in shapes.items():
        if tuple(state[key].shape) != shape or state[key].dtype != torch.float32:
            raise EtmpcError(
                f"{fits}: {key} is {state[key].dtype} of shape {tuple(state[key].shape)}, not torch.float32 of shape {shape}"
            )
    nonfinite = [k for k, v in state.items() if v.is_floating_point() and not bool(torch.isfinite(v).all())]
    if nonfinite:
        raise EtmpcError(f"sb3:{path}: its policy.pth has non-finite weights ({_short(nonfinite[0])})")
    arrays = [np.array(state[k].detach().numpy(), dtype=np.float64) for k in shapes]
    pairs = list(zip(arrays[::2], arrays[1::2]))
    return Network(pairs[:-1], pairs[-1])


def open_network(path: Path, algorithm: str, size: int, actions: int = 2, task: str | None = None) -> Network:
    """The policy network in the Stable-Baselines3 zip ``path``, read as data (see the module's
    docstring); :class:`EtmpcError` (one line) unless it is PPO's ``MlpPolicy`` with ``size`` observations
    and ``actions`` actions (2, or 3 on a task with compute levels; ``task`` is named in the refusal)."""
    if algorithm.lower() != "ppo":
        known = (
            "; etmpc reads PPO's networks (ppo) alone"
            if algorithm.lower() in ALGORITHMS
            else ", which Stable-Baselines3 does not have; etmpc reads PPO's networks (ppo)"
        )
        raise EtmpcError(f"sb3:{path}: {metadata_path(path).name} names the algorithm {algorithm!r}{known}")
    data, blob = _entries(path)
    widths = _architecture(path, data, size, actions, task)
    return _network(path, _state_dict(path, blob), widths, size, actions)
