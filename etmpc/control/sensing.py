"""What a controller measures of the plant's state, and what it makes of it: a :class:`Sensor` (which states
are read, with what noise, bias, quantisation and dropout) and an :class:`ExtendedKalmanFilter` on the MPC's
own predictor that turns its readings into an estimate (:class:`Belief`: mean, covariance, innovation).

A sensor's noise is a function of the episode it is read in (:func:`episode_key`) and its ``seed``: a
policy and the references it is scored against read the same noise on the same stored episode (paired),
whatever process plays it, and a simulation that redraws an episode's future redraws its noise too.

The default :class:`Sensor` is exact: the loop then hands the controller the plant's state itself, and no
filter runs (every number is what it was before sensors existed).

This module may import ``etmpc.common`` and ``etmpc.control.compiled`` (the filter runs as generated C).
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache
import warnings
from typing import Any

import casadi as ca
import numpy as np

from etmpc.common.checks import MAX_SEED, BadValue
from etmpc.common.declared import PER_STATE, Checked, setting
from etmpc.common.numerics import cholesky, matvec
from etmpc.control.compiled import CompiledFunction, CompileError, compile_functions, run


#: The largest value a reading's noise, bias or rounding, or a filter's standard deviation may have, in the state's
#: units: far beyond any plant here (a cart's rail is 5 m), small enough that no square of it overflows.
MAX_READING = 1e3
EACH = (0, 1, PER_STATE)  # a sensor's per-state field: nothing, one value for every state, or one per state


def episode_key(episode: Any) -> int:
    """A 64-bit number that names ``episode`` by its contents (its ``arrays()``, in name order, as little-endian
    bytes): the same stored or drawn episode gives the same key on any machine, in any process."""
    digest = hashlib.blake2b(digest_size=8)
    arrays = episode.arrays() if hasattr(episode, "arrays") else {}
    for name in sorted(arrays):
        value = np.asarray(arrays[name])
        digest.update(name.encode())
        digest.update(np.ascontiguousarray(value, dtype=value.dtype.newbyteorder("<")).tobytes())
    return int.from_bytes(digest.digest(), "little")


@dataclass(frozen=True)
class Readings:
    """An episode's sensor draws, one row per step (``steps + 1``: the state before each step and the last):
    standard normal ``noise`` per state, and whether the step's reading is ``dropped``."""

    noise: np.ndarray
    dropped: np.ndarray


def _per_state(name: str, values: tuple, nx: int, default: float) -> np.ndarray:
    if len(values) == 0:
        return np.full(nx, default, dtype=float)
    if len(values) == 1:
        return np.full(nx, float(values[0]))
    if len(values) != nx:
        raise BadValue(f"a sensor's {name} has one value per state ({nx}) or one for all, got {len(values)}")
    return np.asarray(values, dtype=float)


@dataclass(frozen=True)
class Sensor(Checked):
    """What the controller reads of the state ``x`` at each step: for each state ``i`` that is
    ``measured``, ``y_i = q_i round((x_i + bias_i + noise_std_i e_i) / q_i)`` (``e_i`` standard normal,
    ``q_i`` the ``quantum``, no rounding where it is 0); the whole reading is lost with probability
    ``dropout``. Each per-state field takes one value per state, one value for every state, or nothing
    (no noise, no bias, no rounding; every state measured): checked against the plant's states where the
    system is made. Each field is an option (``--option sensor.noise_std=0.01``), in the state's own units."""

    noise_std: tuple[float, ...] = setting(
        (), lengths=EACH, low=0, high=MAX_READING, unit="state units", why="the reading's noise per state, a standard deviation"
    )
    bias: tuple[float, ...] = setting(
        (), lengths=EACH, low=-MAX_READING, high=MAX_READING, unit="state units", why="a constant error of the reading per state"
    )
    quantum: tuple[float, ...] = setting(
        (),
        lengths=EACH,
        low=0,
        high=MAX_READING,
        unit="state units",
        why="the reading rounded to multiples of this (0: no rounding)",
    )
    measured: tuple[bool, ...] = setting((), lengths=EACH, why="which states are read (the rest only estimated)")
    dropout: float = setting(0.0, low=0, below=1, why="the probability that a step's reading is lost (the filter then predicts)")
    seed: int = setting(0, low=0, high=MAX_SEED, why="the noise stream: with the episode's key, it says every draw")

    def __post_init__(self):
        for name in ("noise_std", "bias", "quantum", "measured"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        super().__post_init__()

    @property
    def exact(self) -> bool:
        """The sensor reads the state itself: every state, no noise, bias, rounding or dropout."""
        zero = lambda values: all(v == 0 for v in values)  # noqa: E731
        return zero(self.noise_std) and zero(self.bias) and zero(self.quantum) and all(self.measured) and self.dropout == 0

    def arrays(self, nx: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(noise_std, bias, quantum, measured)`` as read-only arrays of ``nx`` entries (checked against ``nx``;
        made once per sensor and size: every step's reading uses them)."""
        return _arrays(self, nx)

    def measurement_variance(self, nx: int) -> np.ndarray:
        """The variance a filter assumes per state: the noise's, plus the rounding's (``q^2 / 12``)."""
        std, _, quantum, _ = self.arrays(nx)
        return std**2 + quantum**2 / 12.0

    def readings(self, episode: Any, steps: int, nx: int) -> Readings:
        """The draws of ``episode`` (``steps + 1`` rows), from ``seed`` and the episode's key."""
        rng = np.random.default_rng([self.seed, episode_key(episode)])
        noise = rng.standard_normal((steps + 1, nx))
        dropped = rng.random(steps + 1) < self.dropout
        return Readings(noise, dropped)

    def read(self, x: np.ndarray, readings: Readings, step: int) -> tuple[np.ndarray, np.ndarray]:
        """``(y, seen)``: the reading of state ``x`` at ``step`` (NaN where nothing is read) and which
        entries were read."""
        std, bias, quantum, measured = self.arrays(x.shape[0])
        seen = measured & ~readings.dropped[step]
        y = x + bias + std * readings.noise[step]
        rounded = quantum > 0
        y[rounded] = quantum[rounded] * np.round(y[rounded] / quantum[rounded])
        y[~seen] = np.nan
        return y, seen


@dataclass(frozen=True)
class FilterSettings(Checked):
    """The estimator's model of what it does not know: the process noise's standard deviation per state and
    control interval (the predictor's mismatch and the disturbances, as the filter sees them), and the
    prior's standard deviation per state before the first reading. One value per state or one for all."""

    process_std: tuple[float, ...] = setting(
        (1e-3,),
        lengths=(1, PER_STATE),
        above=0,
        high=MAX_READING,
        unit="state units",
        why="the filter's process noise per state and interval",
    )
    initial_std: tuple[float, ...] = setting(
        (1.0,),
        lengths=(1, PER_STATE),
        above=0,
        high=MAX_READING,
        unit="state units",
        why="the filter's prior standard deviation per state",
    )

    def __post_init__(self):
        for name in ("process_std", "initial_std"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        super().__post_init__()


@lru_cache(maxsize=64)
def _arrays(sensor: Sensor, nx: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    measured = np.ones(nx, bool) if not sensor.measured else _per_state("measured", sensor.measured, nx, 1.0).astype(bool)
    made = (
        _per_state("noise_std", sensor.noise_std, nx, 0.0),
        _per_state("bias", sensor.bias, nx, 0.0),
        _per_state("quantum", sensor.quantum, nx, 0.0),
        measured,
    )
    for array in made:
        array.flags.writeable = False  # shared by every reading of this sensor
    return made


@dataclass(frozen=True, eq=False)
class Belief:
    """What the filter knows after a step's reading: the estimate's ``mean`` and ``covariance``, the
    reading's ``innovation`` (reading minus prediction; NaN where nothing was read), its normalised
    squared size ``nis`` (``nu' S^-1 nu``: chi-square with as many degrees of freedom as entries read, when
    the filter's model is right; 0 when nothing was read) and the ``reading`` itself (NaN where nothing was
    read)."""

    mean: np.ndarray
    covariance: np.ndarray
    innovation: np.ndarray
    reading: np.ndarray
    nis: float = 0.0

    def __post_init__(self):
        for name in ("mean", "covariance", "innovation", "reading"):
            getattr(self, name).flags.writeable = False

    def sample(self, rng: np.random.Generator) -> np.ndarray:
        """A state drawn from the belief, ``N(mean, covariance)``: ``mean + L z`` with ``L`` the covariance's
        Cholesky factor and ``z`` one standard normal draw per state from ``rng``, both by exact sums
        (:mod:`etmpc.common.numerics`: a decision that hinges on the draw is the same on every machine)."""
        root = cholesky(0.5 * (self.covariance + self.covariance.T))
        return self.mean + matvec(root, rng.standard_normal(self.mean.shape[0]))


@dataclass(frozen=True, eq=False)
class ExtendedKalmanFilter:
    """An extended Kalman filter on a discrete model ``x+ = F(x, u)`` (the MPC's predictor: a CasADi
    ``Function``), with process noise of standard deviation ``process_std`` per state and step, and the
    sensor's noise and rounding as the measurement's (the sensor's bias is not known to it: an
    unmodelled error, as a real one is). The prediction linearises ``F`` at the estimate; the
    correction uses Joseph's form, so the covariance stays symmetric and positive. On a linear model it
    is the Kalman filter, optimal for Gaussian noise.

    Its algebra is CasADi expressions (:func:`prediction`, :func:`correction`: one per set of entries read),
    evaluated one scalar operation at a time in a fixed order, never by BLAS or LAPACK: a belief is the same
    to the last bit whatever kernels the CPU's numerical libraries pick. The prediction and the correction
    of the entries the sensor measures are run as C (generated, built once per machine and cached, as the
    MPC is: :mod:`etmpc.control.compiled`); without a C compiler, or for other entries, in CasADi's virtual
    machine, which performs the same operations in the same order and so gives the same bits."""

    model: ca.Function
    sensor: Sensor
    settings: FilterSettings = FilterSettings()
    compiled: bool = True  # run as generated C when a compiler is there; False: CasADi's virtual machine
    process_std: np.ndarray = field(init=False)
    initial_std: np.ndarray = field(init=False)
    nx: int = field(init=False)
    _variance: np.ndarray = field(init=False, repr=False)  # the sensor's measurement variance per state
    _functions: dict = field(init=False, repr=False)  # "predict", or the read entries' mask as bytes -> (function, C)

    def __post_init__(self):
        nx = int(self.model.size1_in(0))
        object.__setattr__(self, "nx", nx)
        object.__setattr__(self, "process_std", _per_state("process_std", self.settings.process_std, nx, 0.0))
        object.__setattr__(self, "initial_std", _per_state("initial_std", self.settings.initial_std, nx, 1.0))
        object.__setattr__(self, "_variance", self.sensor.measurement_variance(nx))  # checked against the size now
        object.__setattr__(self, "_functions", {})

    def start(self, y: np.ndarray, seen: np.ndarray) -> Belief:
        """The belief after the first reading: a prior of mean 0 and ``initial_std``, corrected by it."""
        return self.correct(np.zeros(self.nx), np.diag(self.initial_std**2), y, seen)

    def predict(self, belief: Belief, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The mean and covariance one interval on, under input ``u``."""
        mean, covariance = self._call("predict", belief.mean, u, belief.covariance)
        return mean, covariance

    def step(self, belief: Belief, u: np.ndarray, y: np.ndarray, seen: np.ndarray) -> Belief:
        """Predict over the interval under ``u``, then correct with the reading ``y`` of the entries ``seen``."""
        return self.correct(*self.predict(belief, u), y, seen)

    def correct(self, mean: np.ndarray, covariance: np.ndarray, y: np.ndarray, seen: np.ndarray) -> Belief:
        """The belief after reading ``y``'s entries ``seen`` from the prediction ``(mean, covariance)``."""
        innovation = np.full(self.nx, np.nan)
        if not seen.any():
            return Belief(mean, covariance, innovation, innovation.copy())
        nu = y[seen] - mean[seen]
        corrected, covariance, nis = self._call(np.asarray(seen, dtype=bool).tobytes(), mean, covariance, nu)
        innovation[seen] = nu
        reading = np.full(self.nx, np.nan)
        reading[seen] = y[seen]
        return Belief(corrected, covariance, innovation, reading, float(nis[0]))

    def _call(self, key: str | bytes, *inputs) -> list[np.ndarray]:
        """The prediction (``key`` "predict"), or the correction of the entries whose mask's bytes are ``key``, at
        ``inputs``; its outputs as new arrays (a vector flat, a matrix as a matrix)."""
        function, native = self._function(key)
        outputs = run(function, native, *(np.asarray(v, dtype=float).ravel(order="F") for v in inputs))
        return [_shaped(out, function.size_out(i)) for i, out in enumerate(outputs)]

    def _function(self, key: str | bytes) -> tuple[ca.Function, CompiledFunction | None]:
        """The function of ``key`` and its compiled C (None: CasADi's virtual machine), made at first use: the
        prediction and the measured entries' correction compiled together, once."""
        if key not in self._functions:
            measured = self.sensor.arrays(self.nx)[3]
            if key in ("predict", measured.tobytes()):
                functions = {
                    "predict": prediction(self.model, self.process_std**2),
                    measured.tobytes(): correction(measured, self._variance),
                }
                built = _compiled(list(functions.values())) if self.compiled else [None] * len(functions)
                for (name, function), native in zip(functions.items(), built, strict=True):
                    self._functions[name] = (function, native)
            else:  # entries the sensor does not measure as a rule (never in a task's loop)
                assert isinstance(key, bytes)  # a mask's bytes: "predict" is the one name that is text
                self._functions[key] = (correction(np.frombuffer(key, dtype=bool), self._variance), None)
        return self._functions[key]


def prediction(model: ca.Function, process_variance: np.ndarray) -> ca.Function:
    """``(mean, u, P) -> (F(mean, u), A P A' + Q)``, ``A`` the Jacobian of ``F`` at the mean and ``Q`` the
    process noise's (diagonal) covariance."""
    nx = int(model.size1_in(0))
    x, u, p = ca.SX.sym("x", nx), ca.SX.sym("u", model.size1_in(1)), ca.SX.sym("P", nx, nx)
    x_next = model(x, u)
    a = ca.jacobian(x_next, x)
    covariance = ca.mtimes([a, p, a.T]) + ca.diag(process_variance)
    return ca.Function("etmpc_ekf_predict", [x, u, p], [ca.densify(x_next), ca.densify(covariance)])


def correction(seen: np.ndarray, variance: np.ndarray) -> ca.Function:
    """``(mean, P, nu) -> (mean', P', nis)``: the Kalman correction by the innovation ``nu`` of the entries
    ``seen`` (a mask), in Joseph's form, symmetrised. ``S = P_ss + R = L D L'`` (CasADi's ``ldl``: no square
    root, so a filter driven far from its model, whose ``S`` rounds to indefinite, stays finite, as an LU
    solve does) gives the gain ``K = P_:s S^-1`` and ``nis = nu' S^-1 nu``."""
    nx, read = len(seen), [int(i) for i in np.flatnonzero(seen)]
    mean, p, nu = ca.SX.sym("mean", nx), ca.SX.sym("P", nx, nx), ca.SX.sym("nu", len(read))
    r = ca.diag(variance[read])
    factors = ca.ldl(p[read, read] + r, False)  # D, L' and the order (the given one: no reordering)
    gain = ca.ldl_solve(p[read, :], *factors).T
    keep = ca.SX.eye(nx)
    keep[:, read] = keep[:, read] - gain
    covariance = ca.mtimes([keep, p, keep.T]) + ca.mtimes([gain, r, gain.T])
    outputs = [mean + ca.mtimes(gain, nu), (covariance + covariance.T) / 2, ca.dot(nu, ca.ldl_solve(nu, *factors))]
    name = "etmpc_ekf_correct_" + "".join("1" if s else "0" for s in seen)
    return ca.Function(name, [mean, p, nu], [ca.densify(out) for out in outputs])


def _compiled(functions: list[ca.Function]) -> Sequence[CompiledFunction | None]:
    """``functions`` built together as C; without a C compiler, None for each (CasADi's virtual machine, which
    performs the same operations in the same order: the same bits), with a warning."""
    try:
        return compile_functions(functions)
    except CompileError as exc:
        warnings.warn(f"{exc}; the state estimator runs in CasADi's virtual machine instead (the same numbers)", RuntimeWarning)
        return [None] * len(functions)


def _shaped(values: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """A CasADi output's values (column-major) as a new array: flat for a vector, else ``shape``."""
    rows, cols = shape
    return values.reshape(-1).copy() if cols == 1 else values.reshape((rows, cols), order="F").copy()
