"""Rerun recordings: what is in the file, read back with Rerun's own reader, against the live run."""

import json
import shutil
import uuid

import numpy as np
import pytest
from rerun.chunk import RrdReader

import etmpc.evaluation.evaluate as evaluate_mod
from etmpc.views import blueprint as look
from etmpc.cli import main
from etmpc import evaluate
from etmpc.loop import run_episode
from etmpc.policies import parse_policy
from etmpc.loop.records import prediction_errors
from etmpc.views.replay import read_recording, replay_summary
from etmpc.evaluation.workers import context, policy_rng


def live_and_replayed(tmp_path, domain, policies, episodes=3, repeats=1):
    path = tmp_path / f"{domain}.rrd"
    live = evaluate(domain, policies, episodes=episodes, repeats=repeats, workers=1, progress=False, record=path)
    return live, replay_summary(path), path


@pytest.mark.parametrize(
    "domain, policies, repeats",
    [("cart_pendulum", ["every:3", "threshold:0.3", "always"], 1), ("battery", ["every:5", "threshold:0.01"], 2)],
)
def test_replay_gives_exactly_the_figures_the_run_computed_live(tmp_path, domain, policies, repeats):
    live, replayed, _ = live_and_replayed(tmp_path, domain, policies, repeats=repeats)
    assert len(replayed) == len(live.runs) == len(policies) * 3 * repeats
    by_key = {(r.policy, r.episode, r.repeat): r for r in replayed}
    for run in live.runs:
        again = by_key[(run.policy, run.episode, run.repeat)]
        assert (again.objective, again.control_objective, again.recomputes, again.steps) == (
            run.objective,
            run.control_objective,
            run.recomputes,
            run.steps,
        )  # bit for bit


def test_replay_names_a_recording_by_its_task_not_its_domain(tmp_path, capsys):
    _, replayed, path = live_and_replayed(tmp_path, "cart_pendulum/kicks", ["every:3"], episodes=1)
    assert [(r.domain, r.task) for r in replayed] == [("cart_pendulum", "cart_pendulum/kicks")]
    assert main(["replay", str(path)]) == 0
    assert capsys.readouterr().out.splitlines()[0].startswith("cart_pendulum/kicks: objective")


def test_prediction_error_is_what_the_threshold_trigger_compares(tmp_path):
    """Independent truth: `threshold:X` recomputes by choice exactly where the recorded error
    exceeds X, and keeps its plan exactly where it does not."""
    x = 0.3
    path = tmp_path / "t.rrd"
    evaluate("cart_pendulum", [f"threshold:{x}"], episodes=3, workers=1, progress=False, record=path)
    for data in read_recording(path).values():
        steps, errors = data["prediction_error"]
        _, recompute = data["recompute"]
        _, forced = data["forced"]
        chosen = (recompute[steps] > 0) & (forced[steps] == 0)
        kept = recompute[steps] == 0
        assert chosen.any() and kept.any()
        assert np.all(errors[chosen] > x) and np.all(errors[kept] <= x)
        assert steps[0] == 1  # no plan before step 0


def test_prediction_errors_against_a_direct_computation(cart_system, cart_testset):
    _, env, _ = context("cart_pendulum")
    traj = run_episode(
        cart_system,
        env,
        parse_policy("every:4", cart_system),
        policy_rng(0, 0, 1),
        cart_system.episode_from_arrays(cart_testset.episode_arrays(1)),
    )
    errors = prediction_errors(traj, cart_system.error_weights)
    w = cart_system.error_weights
    for i in range(1, traj.steps):
        k, plan = [p for p in traj.plans if p[0] < i][-1]  # the latest plan made before step i
        assert errors[i] == pytest.approx(np.linalg.norm(w * (traj.states[i] - plan.states[i - k])), abs=1e-15)
    assert np.isnan(errors[0])
    assert np.all(errors[4::4] > 0)  # the plan is 4 steps old when every:4 replaces it


def chunks_by_entity(path):
    out = {}
    for chunk in RrdReader(str(path)).stream():
        out.setdefault(str(chunk.entity_path), []).append(chunk.to_record_batch())
    return out


def column_chunk(entities, entity, column):
    """The one chunk of ``entity`` that holds ``column`` (styles come in chunks of their own)."""
    (batch,) = [b for b in entities[entity] if column in b.schema.names]
    return batch


def series(entities, entity):
    """``(steps, values (rows, series))`` of a scalar entity."""
    batch = column_chunk(entities, entity, "Scalars:scalars")
    return batch.column("step").to_numpy(), np.array(batch.column("Scalars:scalars").to_pylist(), float)


# The recordings the layout tests read: made once, they take a few seconds each.
@pytest.fixture(scope="module")
def cart_recording(tmp_path_factory):
    path = tmp_path_factory.mktemp("cart") / "c.rrd"
    evaluate("cart_pendulum", ["every:5", "always"], episodes=2, workers=1, progress=False, record=path, seed=7)
    return path


@pytest.fixture(scope="module")
def battery_recording(tmp_path_factory):
    path = tmp_path_factory.mktemp("battery") / "b.rrd"
    evaluate("battery", ["never", "threshold:0.01"], episodes=1, workers=1, progress=False, record=path)
    return path


CART = "/cart_pendulum-balance/every\\:5/episode_001/repeat_0"  # entity paths escape the ':' of a policy's name


def test_the_recording_holds_what_happened_and_identity(cart_recording, cart_system, cart_testset):
    entities = chunks_by_entity(cart_recording)
    identity = entities[f"{CART}/identity"][0].to_pydict()
    assert identity["policy"] == [["every:5"]] and identity["episode"] == [[1]] and identity["seed"] == [[7]]
    assert identity["test_set_sha256"] == [[cart_testset.sha256]]

    _, env, _ = context("cart_pendulum")
    traj = run_episode(
        cart_system,
        env,
        parse_policy("every:5", cart_system),
        policy_rng(7, 0, 1),
        cart_system.episode_from_arrays(cart_testset.episode_arrays(1)),
    )
    for j, name in enumerate(cart_system.state_names):
        steps, values = series(entities, f"{CART}/realised/state/{name}")
        np.testing.assert_array_equal(steps, np.arange(traj.steps + 1))
        np.testing.assert_array_equal(values[:, 0], traj.states[: traj.steps + 1, j])
    state = column_chunk(entities, f"{CART}/realised/state/pole_angle", "Scalars:scalars")
    times = state.column("time").to_numpy().astype("timedelta64[ns]").astype(np.int64)
    np.testing.assert_array_equal(times, np.arange(traj.steps + 1) * 100_000_000)  # 0.1 s per step
    _, applied = series(entities, f"{CART}/realised/input/force_n")
    np.testing.assert_array_equal(
        applied, np.column_stack([traj.applied[: traj.steps, 0], np.full(traj.steps, -25.0), np.full(traj.steps, 25.0)])
    )  # applied, then the bounds
    _, correction = series(entities, f"{CART}/correction/force_n")
    np.testing.assert_array_equal(correction[:, 0], traj.correction[: traj.steps, 0])
    assert any(e.startswith("/cart_pendulum-balance/every\\:5/episode_000/") for e in entities)  # episodes stay apart


def plans_in_fan(steps, values, made, predicted):
    """Which series holds each plan (made at ``made[p]``, predicting ``predicted[p]`` from there
    on), found by value; and which plan owns each point (-1: none)."""
    owner = np.full(values.shape, -1)
    slots = []
    for p, (k, prediction) in enumerate(zip(made, predicted)):
        rows = k + np.arange(len(prediction))
        keep = rows <= steps[-1]
        (slot,) = [
            m
            for m in range(values.shape[1])
            if np.array_equal(values[rows[keep], m], prediction[keep]) and (owner[rows[keep], m] == -1).all()
        ]
        owner[rows[keep], slot] = p
        slots.append(slot)
    return slots, owner


@pytest.mark.parametrize("spec, episode, made", [("every:5", 1, list(range(0, 100, 5))), ("always", 0, list(range(100)))])
def test_every_plan_is_a_time_series_from_the_step_it_was_made(cart_recording, cart_system, cart_testset, spec, episode, made):
    """Independent truth: the live run's plans. Each plan's prediction is found whole on the
    ``step`` timeline from the step it was made; no line joins two plans (``always`` starts one
    as the one made 21 steps earlier ends); each point takes its plan's colour, and plans made
    later are coloured otherwise."""
    _, env, _ = context("cart_pendulum")
    traj = run_episode(
        cart_system,
        env,
        parse_policy(spec, cart_system),
        policy_rng(7, 0, episode),
        cart_system.episode_from_arrays(cart_testset.episode_arrays(episode)),
    )
    entities = chunks_by_entity(cart_recording)
    root = f"/cart_pendulum-balance/{spec.replace(':', chr(92) + ':')}/episode_{episode:03d}/repeat_0"
    assert [k for k, _ in traj.plans] == made
    for j, name in enumerate(cart_system.state_names):
        batch = column_chunk(entities, f"{root}/plan/state/{name}", "Scalars:scalars")
        steps = batch.column("step").to_numpy()
        values = np.array(batch.column("Scalars:scalars").to_pylist(), float)
        np.testing.assert_array_equal(steps, np.arange(traj.steps + 1))
        slots, owner = plans_in_fan(steps, values, made, [plan.states[:, j] for _, plan in traj.plans])
        assert np.isnan(values[owner == -1]).all()  # nothing but the plans
        joined = np.isfinite(values[:-1]) & np.isfinite(values[1:])
        assert (owner[:-1][joined] == owner[1:][joined]).all()  # a line never runs from one plan into the next
        colours = np.array(batch.column("SeriesLines:colors").to_pylist(), dtype=np.int64)
        plan_colour = [set(colours[owner == p]) for p in range(len(made))]
        assert all(len(c) == 1 for c in plan_colour) and len({c.pop() for c in plan_colour}) == len(made)
    first, last = (colours[owner == p][0] for p in (0, len(made) - 1))
    rgb = lambda c: ((c >> 24) & 255, (c >> 16) & 255, (c >> 8) & 255)  # noqa: E731
    assert rgb(first)[2] > rgb(first)[1] and rgb(last)[1] > rgb(last)[2]  # blue when made early, green late

    batch = column_chunk(entities, f"{root}/plan/input/force_n", "Scalars:scalars")
    steps = batch.column("step").to_numpy()
    values = np.array(batch.column("Scalars:scalars").to_pylist(), float)
    plans_in_fan(steps, values, made, [plan.inputs[:, 0] for _, plan in traj.plans])  # every plan's inputs, whole
    assert steps[-1] == traj.steps - 1  # inputs end with the last step


def test_always_draws_every_plan(cart_recording):
    """``always`` keeps 21 plans in flight: more than the 20 series the viewer shows by default."""
    entities = chunks_by_entity(cart_recording)
    entity = "/cart_pendulum-balance/always/episode_000/repeat_0/plan/state/pole_angle"
    _, values = series(entities, entity)
    (style,) = [b for b in entities[entity] if "SeriesLines:visible_series" in b.schema.names]
    visible = style.column("SeriesLines:visible_series").to_pylist()[0]
    assert values.shape[1] > 20 and visible == [True] * values.shape[1]
    assert (np.isfinite(values).sum(axis=1) > 20).any()


def test_battery_recording_holds_prices_production_and_each_plans_forecasts(battery_recording, battery_testset):
    entities = chunks_by_entity(battery_recording)
    root = "/battery-trading/never/episode_000/repeat_0"
    episode = battery_testset.episode_arrays(0)
    _, price = series(entities, f"{root}/realised/signal/price_eur_kwh")
    _, production = series(entities, f"{root}/realised/signal/net_production_kw")
    np.testing.assert_array_equal(price[:, 0], episode["price_eur_kwh"][:100])
    np.testing.assert_array_equal(production[:, 0], episode["production_kw"][:100])
    # `never` plans at 0, 20, 40, ...: the forecasts each was made with, under the signal they forecast.
    for signal, forecasts in (("price_eur_kwh", "price_forecast_eur_kwh"), ("net_production_kw", "production_forecast_kw")):
        steps, values = series(entities, f"{root}/forecast/{signal}")
        plans_in_fan(steps, values, [0, 20, 40, 60, 80], [episode[forecasts][k][:20] for k in (0, 20, 40, 60, 80)])


def test_recomputes_are_points_of_their_kind_and_log_lines_with_their_detail(battery_recording):
    entities = chunks_by_entity(battery_recording)
    root = "/battery-trading/never/episode_000/repeat_0"
    decision_steps, decision = series(entities, f"{root}/decision")
    recompute, forced = decision[:, 0] > 0, decision[:, 1] > 0
    assert list(np.flatnonzero(recompute)) == [0, 20, 40, 60, 80] and list(np.flatnonzero(forced)) == [0, 20, 40, 60, 80]
    steps, kinds = series(entities, f"{root}/recompute")  # chosen, forced, first: NaN where another kind
    assert list(steps) == [0, 20, 40, 60, 80]
    assert np.isnan(kinds[:, 0]).all()  # `never` chooses none
    np.testing.assert_array_equal(kinds[1:, 1], [20, 20, 20, 20])  # forced: the plan was 20 steps old
    assert kinds[0, 2] == 0 and np.isnan(kinds[0, :2]).all() and np.isnan(kinds[1:, 2]).all()
    text = column_chunk(entities, f"{root}/events", "TextLog:text").column("TextLog:text").to_pylist()
    error_steps, errors = series(entities, f"{root}/prediction_error")
    assert text[0] == ["first plan"]
    for i, line in zip(steps[1:], text[1:]):
        assert line[0] == f"FORCED, the plan ran out: plan age 20, ‖W (x − x̂)‖ {errors[error_steps == i, 0][0]:.4g}"

    root = "/battery-trading/threshold\\:0.01/episode_000/repeat_0"
    steps, kinds = series(entities, f"{root}/recompute")
    _, decision = series(entities, f"{root}/decision")
    chosen = np.flatnonzero((decision[:, 0] > 0) & (decision[:, 1] == 0))
    np.testing.assert_array_equal(steps[np.isfinite(kinds[:, 0])], chosen)
    error_steps, errors = series(entities, f"{root}/prediction_error")
    assert (errors[np.isin(error_steps, chosen), 0] > 0.01).all()
    _, threshold = series(entities, f"{root}/threshold")
    assert (threshold == 0.01).all()


# -- the blueprint ----------------------------------------------------------------------------------
def read_blueprint(path):
    """The blueprint in a file, read back: ``{"root": [tabs]}`` as a tree of ``{"kind", "name",
    "children"}`` containers and ``{"class", "name", "origin", "contents", "properties"}`` views."""
    reader = RrdReader(str(path))
    (store,) = reader.blueprints()
    items, root = {}, None
    for chunk in reader.stream(store=store):
        batch = chunk.to_record_batch()
        row = {name: batch.column(name).to_pylist()[-1] for name in batch.schema.names if ":" in name}
        parts = str(chunk.entity_path).strip("/").split("/")
        if parts[0] == "viewport":
            root = str(uuid.UUID(bytes=bytes(row["ViewportBlueprint:root_container"][0])))
        elif parts[0] == "time_panel":
            items["time_panel"] = row
        elif parts[0] in ("view", "container"):
            item = items.setdefault(parts[1], {"properties": {}})
            if len(parts) == 2:
                item.update(row)
            else:
                item["properties"][parts[2]] = row

    def node(key):
        item = items[key]
        if "ContainerBlueprint:container_kind" in item:
            kind = {1: "tabs", 2: "horizontal", 3: "vertical", 4: "grid"}[item["ContainerBlueprint:container_kind"][0]]
            return {
                "kind": kind,
                "name": (item.get("ContainerBlueprint:display_name") or [None])[0],
                "children": [node(c.split("/")[1]) for c in item["ContainerBlueprint:contents"]],
            }
        contents = item["properties"].get("ViewContents", {}).get("ViewContents:query", [])
        return {
            "class": item["ViewBlueprint:class_identifier"][0],
            "name": item["ViewBlueprint:display_name"][0],
            "origin": item["ViewBlueprint:space_origin"][0],
            "contents": contents,
            "properties": item["properties"],
        }

    return node(root), items["time_panel"]


def views_of(node):
    return [node] if "class" in node else [v for child in node["children"] for v in views_of(child)]


def tabs_of(node):
    assert node["kind"] == "tabs"
    return {child["name"]: child for child in node["children"]}


def test_the_blueprint_has_a_tab_per_policy_and_episode_of_time_series_of_entities_in_the_file(cart_recording):
    root, time_panel = read_blueprint(cart_recording)
    written = set(chunks_by_entity(cart_recording))
    policies = tabs_of(root)
    assert list(policies) == ["every:5", "always"]
    assert time_panel["TimePanelBlueprint:timeline"] == ["step"]
    for policy, policy_tab in policies.items():
        episodes = tabs_of(policy_tab)
        assert list(episodes) == ["episode 0", "episode 1"]
        for e, (name, tab) in enumerate(episodes.items()):
            episode_root = f"/cart_pendulum-balance/{policy.replace(':', chr(92) + ':')}/episode_{e:03d}/repeat_0"
            views = views_of(tab)
            assert {v["class"] for v in views} == {"TimeSeries", "TextDocument", "TextLog"}  # no 2-D ("2D") views
            for view in views:
                for query in view["contents"]:  # an entity's path, or "$origin/**": the origin's subtree
                    entity = query.replace("$origin", view["origin"]).removesuffix("/**")
                    assert entity in written and entity.startswith(episode_root + "/"), (name, view["name"], entity)
                if view["class"] == "TimeSeries":  # the whole episode, whatever the timeline; no legend over the data
                    assert view["properties"]["TimeAxis"]["TimeAxis:view_range"] == [{"start": None, "end": None}]
                    assert view["properties"]["PlotLegend"]["PlotLegend:visible"] == [False]
            by_name = {v["name"]: v for v in views}
            title = [v for v in views if v["class"] == "TextDocument"]
            assert [v["origin"] for v in title] == [f"{episode_root}/about"]
            about = column_chunk(chunks_by_entity(cart_recording), f"{episode_root}/about", "TextDocument:text")
            assert f"**{policy}**" in about.column("TextDocument:text").to_pylist()[0][0]
            assert f"test-set episode {e}" in about.column("TextDocument:text").to_pylist()[0][0]
            for state, label in (("cart_position", "cart position [m]"), ("pole_angle", "pole angle [rad]")):
                (view,) = [v for n, v in by_name.items() if n.startswith(label)]
                assert view["contents"] == [f"{episode_root}/realised/state/{state}", f"{episode_root}/plan/state/{state}"]
            (force,) = [v for n, v in by_name.items() if n.startswith("force [N]")]
            assert force["contents"] == [f"{episode_root}/realised/input/force_n", f"{episode_root}/plan/input/force_n"]
            panels = [set(v["contents"]) for v in views if v["class"] == "TimeSeries"]
            # Series of different scales have panels of their own.
            for alone in (
                "objective/reward",
                "objective/running",
                "correction/force_n",
                "realised/signal/disturbance_rad_s2",
                "recompute",
                "prediction_error",
            ):
                assert {f"{episode_root}/{alone}"} in panels


def test_the_battery_forecast_panels_show_the_signal_they_forecast(battery_recording):
    root, _ = read_blueprint(battery_recording)
    written = set(chunks_by_entity(battery_recording))
    for policy, tab in tabs_of(root).items():
        episode_root = f"/battery-trading/{policy.replace(':', chr(92) + ':')}/episode_000/repeat_0"
        views = views_of(tab)
        for view in views:
            assert all(q.replace("$origin", view["origin"]).removesuffix("/**") in written for q in view["contents"])
        for signal in ("price_eur_kwh", "net_production_kw"):
            (view,) = [v for v in views if f"{episode_root}/forecast/{signal}" in v["contents"]]
            assert view["contents"] == [f"{episode_root}/realised/signal/{signal}", f"{episode_root}/forecast/{signal}"]
            low, high = view["properties"]["ScalarAxis"]["ScalarAxis:range"][0]
            _, true = series(chunks_by_entity(battery_recording), f"{episode_root}/realised/signal/{signal}")
            assert low < true.min() and true.max() < high
        (error,) = [v for v in views if f"{episode_root}/prediction_error" in v["contents"]]
        assert (f"{episode_root}/threshold" in error["contents"]) == policy.startswith("threshold")


def test_an_episode_tab_per_episode_up_to_the_limit(tmp_path):
    layouts = [
        look.EpisodeLayout(
            root=f"/battery-trading/always/episode_{e:03d}/repeat_0",
            domain="battery",
            policy="always",
            episode=e,
            repeat=0,
            steps=100,
            control_interval_s=10.0,
            states=("state_of_charge",),
            inputs=(),
            signals=(),
            forecast_signals=(),
            entities=frozenset({"realised/state/state_of_charge"}),
        )
        for e in range(look.MAX_EPISODE_TABS + 3)
    ]
    tabs = look.blueprint(layouts).root_container
    assert [tab.name for tab in tabs.contents] == [f"episode {e}" for e in range(look.MAX_EPISODE_TABS)]


def test_policies_are_named_for_people(tmp_path):
    assert look.policy_label("rl:results/x/seed0/last.json") == "rl:last"
    assert look.policy_label("rollout:rl:policies/battery/trading/learned.json:4:20") == "rollout:rl:learned:4:20"
    assert look.policy_label("threshold:0.3") == "threshold:0.3"
    assert look.label("pole_angle") == "pole angle [rad]" and look.label("inflow_kw") == "inflow [kW]"
    # Two learned policies with the same file stem stay apart; the identity keeps each exact spec.
    copy = tmp_path / "learned.json"
    shutil.copy("policies/battery/trading/learned.json", copy)
    specs = ["rl:policies/battery/trading/learned.json", f"rl:{copy}"]
    path = tmp_path / "rl.rrd"
    live = evaluate("battery", specs, episodes=1, workers=1, progress=False, record=path)
    entities = chunks_by_entity(path)
    for spec, part in zip(specs, ["rl\\:learned", "rl\\:learned\\ \\(2\\)"]):
        identity = entities[f"/battery-trading/{part}/episode_000/repeat_0/identity"][0].to_pydict()
        assert identity["policy"] == [[spec]]
    replayed = {r.policy: r.objective for r in replay_summary(path)}
    assert replayed == {r.policy: r.objective for r in live.runs}
    assert [tab["name"] for tab in read_blueprint(path)[0]["children"]] == ["rl:learned", "rl:learned (2)"]


def test_an_interrupted_recording_leaves_no_file(tmp_path, monkeypatch):
    def broken(*args, **kwargs):
        raise RuntimeError("worker died")

    monkeypatch.setattr(evaluate_mod, "run_jobs", broken)
    with pytest.raises(RuntimeError):
        evaluate("battery", ["always"], episodes=1, workers=1, progress=False, record=tmp_path / "x.rrd")
    assert list(tmp_path.iterdir()) == []


def test_replay_cli_prints_the_figures_and_refuses_bad_files(tmp_path, capsys):
    path = tmp_path / "b.rrd"
    assert (
        main(["evaluate", "--task", "battery", "--policy", "every:5", "--episodes", "2", "--workers", "1", "--record", str(path)])
        == 0
    )
    capsys.readouterr()
    assert main(["replay", str(path), "--per-episode"]) == 0
    out = capsys.readouterr().out
    assert "every:5" in out and "episode 1 repeat 0" in out
    (tmp_path / "junk.rrd").write_bytes(b"not a recording")
    for argv in (
        ["replay", str(tmp_path / "missing.rrd")],
        ["replay", str(tmp_path / "junk.rrd")],
        ["evaluate", "--task", "battery", "--policy", "always", "--record", str(tmp_path / "x.txt")],
    ):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1, err


def test_render_puts_the_video_frames_into_the_recording(tmp_path, capsys):
    out, rec = tmp_path / "v.mp4", tmp_path / "v.rrd"
    argv = [
        "render",
        "--task",
        "cart_pendulum",
        "--policy",
        "every:5",
        "--episode",
        "3",
        "--out",
        str(out),
        "--width",
        "160",
        "--height",
        "120",
        "--record",
        str(rec),
    ]
    assert main(argv) == 0
    assert "101 frames" in capsys.readouterr().out
    images = [
        b
        for e, batches in chunks_by_entity(rec).items()
        if e.endswith("/camera")
        for b in batches
        if "EncodedImage:blob" in b.schema.names
    ]
    steps = sorted(s for b in images for s in b.column("step").to_pylist())
    assert steps == list(range(101))
    spatial = [v["origin"] for v in views_of(read_blueprint(rec)[0]) if v["class"] == "2D"]
    assert spatial == ["/cart_pendulum-balance/every\\:5/episode_003/repeat_0/camera"]  # the only 2-D view: the video
    (replayed,) = replay_summary(rec)
    live = evaluate("cart_pendulum", ["every:5"], episodes=4, workers=1, progress=False).runs[3]
    assert (replayed.episode, replayed.objective, replayed.recomputes) == (3, live.objective, live.recomputes)
    assert main(["render", "--task", "cart_pendulum", "--policy", "every:5", "--out", str(tmp_path / "v.avi")]) == 2


def test_train_records_its_evaluations_without_changing_any_result(tmp_path):
    from etmpc.learning.train import TrainConfig, train
    from etmpc.views.curves import write_curve_png
    from etmpc.views.recording import Recorder

    config = TrainConfig(
        "battery", seeds=(0, 1), episodes=4, eval_every=2, eval_episodes=3, normalisation_episodes=2, validation_episodes=2
    )
    views = dict(recorder=Recorder, curve_png=write_curve_png)
    train(config, tmp_path / "plain", workers=1, progress=False, **views)
    train(config, tmp_path / "rec", workers=1, progress=False, record_episodes=2, **views)
    plain = {p.relative_to(tmp_path / "plain"): p.read_bytes() for p in (tmp_path / "plain").rglob("*") if p.is_file()}
    recorded = {p.relative_to(tmp_path / "rec"): p.read_bytes() for p in (tmp_path / "rec").rglob("*") if p.is_file()}
    assert {k: v for k, v in recorded.items() if k.parts[0] != "recordings"} == plain
    assert sorted(p.name for p in (tmp_path / "rec" / "recordings").iterdir()) == [
        "eval_00000.rrd",
        "eval_00002.rrd",
        "eval_00004.rrd",
    ]

    replayed = replay_summary(tmp_path / "rec" / "recordings" / "eval_00004.rrd")
    assert sorted((r.policy, r.episode) for r in replayed) == [(f"seed{s}/episodes00004", e) for s in (0, 1) for e in (0, 1)]
    live = evaluate("battery", [f"rl:{tmp_path / 'rec' / 'seed1' / 'last.json'}"], episodes=2, workers=1, progress=False)
    again = [r for r in replayed if r.policy == "seed1/episodes00004"]
    assert [(r.objective, r.recomputes) for r in again] == [(r.objective, r.recomputes) for r in live.runs]


def test_a_self_trigger_records_what_it_announced_at_each_solve(tmp_path, cart_system):
    """Independent truth: the loop keeps a self-trigger's plan exactly as long as announced, so each
    announcement recorded at a solve is the gap to the next recompute in the file's own decisions."""
    from etmpc.policies import selftrigger as st

    played = evaluate_mod.play_test_episode("cart_pendulum", parse_policy("always", cart_system), 0, 0, 0)
    env = cart_system.make_env()
    env.task.use_episode(played.episode)
    timestep = env.reset()
    p = st.plan_features(cart_system.plan(cart_system.state(timestep), np.zeros(1), None, 0, timestep)).size
    theta = np.zeros((len(st.CANDIDATES), 1 + p))
    theta[st.CANDIDATES.index(2), 3], theta[st.CANDIDATES.index(6), 3] = 1.0, -1.0  # by the sign of the pole angle
    policy_file = tmp_path / "announcing.json"
    policy_file.write_text(
        json.dumps(st.SelfTrigger("x", "cart_pendulum", st.CANDIDATES, theta, np.zeros(p), np.ones(p)).to_json())
    )
    path = tmp_path / "s.rrd"
    evaluate("cart_pendulum", [f"self:{policy_file}"], episodes=1, workers=1, progress=False, record=path)
    entities = chunks_by_entity(path)
    root = "/cart_pendulum-balance/self\\:announcing/episode_000/repeat_0"
    _, decision = series(entities, f"{root}/decision")
    solves = np.flatnonzero(decision[:, 0] > 0)
    steps, announced = series(entities, f"{root}/announced")
    np.testing.assert_array_equal(steps, solves)
    assert set(announced[:, 0]) == {2, 6}
    np.testing.assert_array_equal(announced[:-1, 0], np.diff(solves))
    assert len(decision) - solves[-1] <= announced[-1, 0]  # the last plan is cut short by the episode's end
    text = column_chunk(entities, f"{root}/events", "TextLog:text").column("TextLog:text").to_pylist()
    for k, n, (line,) in zip(solves, announced[:, 0].astype(int), text):
        assert line.endswith(f"announced: keep {n} steps, next solve at step {k + n}")
    root_view, _ = read_blueprint(path)
    (recompute_view,) = [v for v in views_of(root_view) if v["class"] == "TimeSeries" and v["name"].startswith("recomputes")]
    assert f"{root}/announced" in recompute_view["contents"]


def test_a_noisy_run_records_the_plant_its_estimate_and_the_readings_side_by_side(tmp_path):
    from etmpc.systems import system_key

    options = {"sensor.noise_std": "0.01,0,0.01,0", "sensor.measured": "1,0,1,0"}
    key = system_key("cart_pendulum/kicks", None, options)
    path = tmp_path / "noisy.rrd"
    evaluate(key, ["every:3"], episodes=1, workers=1, progress=False, record=path)
    system = key.make()
    _, env, testset = context(key)
    traj = run_episode(
        system, env, parse_policy("every:3", system), policy_rng(0, 0, 0), system.episode_from_arrays(testset.episode_arrays(0))
    )
    entities = chunks_by_entity(path)
    root = "/cart_pendulum-kicks/every\\:3/episode_000/repeat_0"
    identity = entities[f"{root}/identity"][0].to_pydict()
    assert identity["options"] == [["--option sensor.measured=true,false,true,false --option sensor.noise_std=0.01,0.0,0.01,0.0"]]
    for j, name in enumerate(system.state_names):
        _, values = series(entities, f"{root}/realised/state/{name}")
        n = traj.steps + 1
        np.testing.assert_array_equal(values[:, 0], traj.states[:n, j])  # what happened
        np.testing.assert_array_equal(values[:, 1], traj.estimates[:n, j])  # the filter's estimate
        np.testing.assert_array_equal(values[:, 2], traj.measurements[:n, j])  # the readings (NaN: not read)
        assert np.isnan(values[:, 2]).all() == (name in ("cart_velocity", "pole_angular_velocity"))
