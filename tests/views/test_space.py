"""The recordings' 3-D view (etmpc.views.space): a quadrotor episode's flight, plans, waypoint, gusts and
geofence read back from the file, against the live run and the test set; a task without a space gets none."""

import pickle

import numpy as np
import pytest

from etmpc import evaluate
from etmpc.evaluation.workers import play_test_episode
from etmpc.policies import parse_policy
from etmpc.systems import make_system
from etmpc.systems.space import Space
from etmpc.loop.records import EpisodeRecord
from tests.views.test_recording import chunks_by_entity, column_chunk, read_blueprint, views_of

ROOT = "/quadrotor-waypoints/every\\:5/episode_000/repeat_0"
SPACE = f"{ROOT}/space"


@pytest.fixture(scope="module")
def quadrotor(tmp_path_factory):
    """``(entities of the recording, its blueprint, the live run)``: test-set episode 0 under every:5 (gusts at
    steps 4-13 and 38-48, three waypoints)."""
    path = tmp_path_factory.mktemp("quadrotor") / "q.rrd"
    evaluate("quadrotor", ["every:5"], episodes=1, workers=1, progress=False, record=path)
    system = make_system("quadrotor")
    played = play_test_episode("quadrotor", parse_policy("every:5", system), 0, 0, 0)
    return chunks_by_entity(path), read_blueprint(path)[0], played


def points(entities, entity, component):
    """``(steps, [values (k, 3) per step])`` of a temporal 3-D component."""
    batch = column_chunk(entities, entity, component)
    return batch.column("step").to_numpy(), [np.array(v, float).reshape(-1, 3) for v in batch.column(component).to_pylist()]


def test_the_flight_is_a_line_and_a_point_per_step_where_the_drone_was(quadrotor):
    entities, _, played = quadrotor
    flight = played.trajectory.states[: played.trajectory.steps + 1, :3]  # x_m, y_m, z_m
    (path,) = [b for b in entities[f"{SPACE}/path"] if "LineStrips3D:strips" in b.schema.names]
    np.testing.assert_array_equal(np.array(path.column("LineStrips3D:strips").to_pylist()[0][0]), flight.astype(np.float32))
    steps, positions = points(entities, f"{SPACE}/position", "Points3D:positions")
    np.testing.assert_array_equal(steps, np.arange(101))
    np.testing.assert_array_equal(np.vstack(positions), flight.astype(np.float32))  # one point per step
    times = column_chunk(entities, f"{SPACE}/position", "Points3D:positions").column("time").to_numpy()
    np.testing.assert_array_equal(times.astype("timedelta64[ns]").astype(np.int64), np.arange(101) * 50_000_000)


def test_each_plan_is_a_line_of_its_predicted_positions_from_the_step_it_was_made(quadrotor):
    entities, _, played = quadrotor
    batch = column_chunk(entities, f"{SPACE}/plan", "LineStrips3D:strips")
    made = [k for k, _ in played.trajectory.plans]
    assert made == list(range(0, 100, 5))
    np.testing.assert_array_equal(batch.column("step").to_numpy(), made)
    strips = batch.column("LineStrips3D:strips").to_pylist()
    assert len(strips) == len(made)
    for (strip,), (_, plan) in zip(strips, played.trajectory.plans):
        np.testing.assert_array_equal(np.array(strip), plan.states[:, :3].astype(np.float32))
    colours = [c for (c,) in batch.column("LineStrips3D:colors").to_pylist()]
    assert len(set(colours)) == len(made)  # each plan coloured by when it was made, as its time series


def test_the_waypoint_is_the_episodes_and_the_gust_an_arrow_from_the_drone_half_a_metre_per_015_n(quadrotor):
    entities, _, played = quadrotor
    n = played.trajectory.steps
    steps, targets = points(entities, f"{SPACE}/target", "Points3D:positions")
    np.testing.assert_array_equal(steps, np.arange(n))
    np.testing.assert_array_equal(np.vstack(targets), played.episode.target[:n].astype(np.float32))
    (style,) = [b for b in entities[f"{SPACE}/target"] if "Points3D:colors" in b.schema.names]
    rgba = style.column("Points3D:colors").to_pylist()[0][0]
    assert (rgba >> 24) & 255 > 200 and (rgba >> 16) & 255 < 80 and (rgba >> 8) & 255 < 80  # red

    gust = played.episode.gusts()[:n]  # (steps, 3) N, world frame, z always 0
    steps, vectors = points(entities, f"{SPACE}/force", "Arrows3D:vectors")
    _, origins = points(entities, f"{SPACE}/force", "Arrows3D:origins")
    np.testing.assert_array_equal(steps, np.arange(n))
    blowing = np.linalg.norm(gust, axis=1) > 0
    assert blowing.sum() == 21 and [len(v) for v in vectors] == list(blowing.astype(int))  # none where no gust
    np.testing.assert_allclose(np.vstack(vectors), gust[blowing] * 0.5 / 0.15, rtol=1e-6, atol=1e-8)
    np.testing.assert_array_equal(np.vstack(origins), played.trajectory.states[:n, :3][blowing].astype(np.float32))


def test_the_geofence_is_a_static_box(quadrotor):
    entities, _, _ = quadrotor
    (box,) = entities[f"{SPACE}/box"]
    assert box.column("Boxes3D:centers").to_pylist() == [[[0.0, 0.0, 1.25]]]  # |x|, |y| <= 2, 0 <= z <= 2.5
    assert box.column("Boxes3D:half_sizes").to_pylist() == [[[2.0, 2.0, 1.25]]]
    assert "step" not in box.schema.names


def test_the_episode_tab_has_a_3d_view_of_the_space_first(quadrotor):
    entities, root, _ = quadrotor
    views = views_of(root)
    (view,) = [v for v in views if v["class"] == "3D"]
    assert view["origin"] == SPACE and view["contents"] == ["$origin/**"]
    assert {e for e in entities if e.startswith(SPACE)} == {
        SPACE,
        *(f"{SPACE}/{p}" for p in ("path", "position", "plan", "target", "force", "box")),
    }
    assert views[1] is view  # after the title line, before the time series


def test_a_task_without_a_space_records_no_3d_view(tmp_path, cart_system):
    assert getattr(cart_system, "space", None) is None
    path = tmp_path / "c.rrd"
    evaluate("cart_pendulum", ["every:5"], episodes=1, workers=1, progress=False, record=path)
    assert not [e for e in chunks_by_entity(path) if "space" in e]
    assert {v["class"] for v in views_of(read_blueprint(path)[0])} == {"TimeSeries", "TextDocument", "TextLog"}


def test_a_space_travels_with_the_episode_record_and_says_three_names_each():
    system = make_system("quadrotor")
    played = play_test_episode("quadrotor", parse_policy("never", system), 0, 0, 0)
    record = EpisodeRecord.from_trajectory(system, played.trajectory, {"policy": "never"}, played.episode)
    assert record.space is system.space and pickle.loads(pickle.dumps(record)).space == system.space
    assert system.space.position == system.state_names[:3] == ("x_m", "y_m", "z_m")
    with pytest.raises(ValueError, match="three entries"):
        Space(position=("x_m", "y_m"))
    with pytest.raises(ValueError, match="at least one"):
        Space(position=("x_m", "y_m", "z_m"), force=(None, None, None))
