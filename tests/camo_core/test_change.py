"""Continuous camouflage without ROS: when a robot notices a changed scene, and the rounds that
robots start by themselves, each equal to the simulator on its frame with its seed."""

import random

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from camo_core.algorithm.backgrounds import background
from camo_core.algorithm.change import Watch, noticed, params_of_round, round_seed
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.sensing import ProjectedSensor, Projection, sense_image
from camo_core.algorithm.simulator import simulate
from camo_core.swarm.mailbox import Mailbox
from camo_core.swarm.protocol import StepProtocol
from camo_core.swarm.robot_io import DONE, NOTHING, SENSING, Message
from camo_core.swarm.run_setup import ProtocolParams

WINDOW, THRESHOLD = ProtocolParams().change_window, ProtocolParams().change_threshold  # a run's


def watch_of(count: int, rho_meas: float = 0.0, seed: int = 0) -> Watch:
    params = CamoParams(rows=1, cols=count, rho_meas=rho_meas, seed=seed)
    return Watch(np.arange(count), params, WINDOW, THRESHOLD)


@settings(max_examples=300, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.one_of(st.floats(0, 255), st.sampled_from([10.0, 11.0, 200.0, 201.0])),
            st.booleans(),  # a new frame (else the last one read again)
        ),
        min_size=0,
        max_size=48,
    ),
    st.booleans(),
)
def test_the_vectorised_watch_notices_where_the_plain_rule_does(readings, idle):
    watch = watch_of(1)
    values, frames, frame, value = [], [], 0, 0.0
    for new_value, new_frame in readings:
        if new_frame or not frames:  # a frame read again reads the same
            frame, value = frame + 1, new_value
        values.append(value)
        frames.append(frame)
    at = None
    for k, (value, frame) in enumerate(zip(values, frames, strict=True)):
        judged = watch.read(np.array([[value]]), frame, np.array([idle]))
        if len(judged.robots):
            at = k
            break
    assert at == noticed(values, WINDOW, THRESHOLD, idle, frames)


def test_a_static_scene_with_sensor_noise_is_never_taken_for_a_change():
    # 256 robots, 15% of every reading replaced by noise, 6000 readings each (10 minutes at 10
    # readings a second): not one notice.
    watch = watch_of(256, rho_meas=0.15, seed=3)
    grid = np.linspace(20, 235, 256).reshape(1, 256)
    notices = sum(len(watch.read(grid, 0).robots) for _ in range(6000))
    assert notices == 0
    assert np.isfinite(watch.reference).mean() > 0.99  # they did find their reference


def test_a_camera_s_frame_noise_raises_the_threshold_and_is_not_a_change():
    generator = np.random.default_rng(1)
    watch = watch_of(256)
    base = np.linspace(20, 235, 256).reshape(1, 256)
    notices = sum(
        len(watch.read(base + generator.normal(0, 8, base.shape), k).robots) for k in range(3000)
    )
    assert notices == 0
    assert 6 < np.median(watch.sigma()) < 10


class NoisyCamera:
    """A static scene through a camera whose frames each add noise of sigma `noise`, a new frame
    every `every` readings, read by 256 robots with sensor noise (rho_meas 0.15)."""

    def __init__(self, noise: float, every: int, seed: int) -> None:
        self.generator = np.random.default_rng(seed)
        self.watch = watch_of(256, rho_meas=0.15, seed=seed)
        self.base = np.linspace(20, 235, 256).reshape(1, 256)
        self.noise, self.every = noise, every
        self.frame, self.grid = -1, self.base

    def read(self, k: int) -> int:
        """Reading k; the robots that noticed start a round on the newest frame (and take their
        reference from it again): how many did."""
        if k % self.every == 0:
            self.frame += 1
            self.grid = self.base + self.generator.normal(0, self.noise, self.base.shape)
        judged = self.watch.read(self.grid, self.frame)
        self.watch.reset(judged.robots, self.grid, self.frame)
        return len(judged.robots)


def test_frames_slower_than_the_readings_are_not_taken_for_a_change():
    # Each frame read three times: two of three differences of successive readings were 0, the
    # estimated noise fell to 0 and the threshold with it, under the frames' own noise.
    camera = NoisyCamera(noise=8, every=3, seed=4)
    assert sum(camera.read(k) for k in range(3000)) == 0
    assert np.median(camera.watch.sigma()) > 6  # the threshold above the frames' noise


def test_joining_rounds_leaves_the_noise_and_takes_no_false_alarm():
    # A join reads the round's one frame a window's worth of times (8 to 64): those copies were
    # taken for readings without noise, and the threshold fell after every join.
    camera = NoisyCamera(noise=8, every=1, seed=6)
    notices = 0
    for k in range(3000):
        notices += camera.read(k)
        if k % 50 == 49:  # every robot joins a round of the newest frame
            camera.watch.reset(np.arange(256), camera.grid, camera.frame)
    assert notices == 0


def test_a_round_s_one_frame_off_by_its_noise_is_not_kept_as_the_reference():
    # Robots join a round on a frame 30 grey levels off the scene (within its camera's noise,
    # sigma 10: threshold 60); later the camera's noise falls (threshold 24): the frames were a
    # change against that one frame, and every robot started a false round.
    generator = np.random.default_rng(7)
    watch = watch_of(64)
    scene = np.linspace(40, 200, 64).reshape(1, 64)
    notices = 0
    for k in range(400):
        noisy = scene + generator.normal(0, 10 if k < 220 else 1, scene.shape)
        judged = watch.read(noisy, k)
        notices += len(judged.robots) if k >= 220 else 0  # once the noise has fallen
        watch.reset(judged.robots, noisy, k)
        if k == 199:  # the round of this frame, off by 30 everywhere
            watch.reset(np.arange(64), scene + 30, k)
    assert notices == 0 and np.median(watch.sigma()) < 2
    assert np.abs(watch.reference - scene[0]).max() < 15  # the frames' level, not the one frame


def test_a_still_image_s_frames_that_change_are_each_noticed():
    # Frames only at changes, one a second (a still image, then another, as Camouflage goals or
    # --images project them): they are the scene's changes, not its noise, however many come.
    watch = watch_of(64)
    levels = np.random.default_rng(3).uniform(20, 235, (60, 1, 64))
    for frame in range(60):
        reference, noticed_now = watch.reference.copy(), set()
        for _ in range(10):
            judged = watch.read(levels[frame], frame)
            noticed_now |= set(judged.robots.tolist())
            watch.reset(judged.robots, levels[frame], frame)
        with np.errstate(invalid="ignore"):  # every robot whose cell moved beyond the threshold
            moved = np.abs(levels[frame][0] - reference) > THRESHOLD
        assert set(np.flatnonzero(moved).tolist()) <= noticed_now, frame
    assert not watch.sigma().any()
    assert not watch.sigma().any()


@pytest.mark.parametrize("rho", [0.0, 0.15])
def test_a_switched_scene_is_noticed_within_a_window_of_readings_despite_noise(rho):
    watch = watch_of(64, rho_meas=rho, seed=5)
    before, after = np.full((1, 64), 60.0), np.full((1, 64), 190.0)
    for k in range(20):
        assert not len(watch.read(before, k).robots)
    first = None
    for k in range(20):
        judged = watch.read(after, 20 + k)
        if len(judged.robots):
            first = k
            if not rho:  # where the new level was first read: the switch
                assert set(judged.changed_frames.tolist()) == {20}
            break
    assert first is not None and first < WINDOW


def test_an_idle_robot_notices_the_scene_once_it_has_a_level():
    watch = watch_of(3)
    grid = np.array([[10.0, 100.0, 250.0]])
    seen = [len(watch.read(grid, 0, np.ones(3, bool)).robots) for _ in range(2 * WINDOW)]
    assert seen == [0] * (2 * WINDOW - 1) + [3]  # two windows: a level, and a noise to judge by


def test_round_seeds_follow_the_round_and_round_0_keeps_the_run_s():
    params = CamoParams(seed=2**64 - 1)
    assert params_of_round(params, 0) is params
    assert params_of_round(params, 2).seed == round_seed(2**64 - 1, 2) == 1


class Scene:
    """Robots of one process on a projection whose frames change, each watching its readings
    (the process's Watch) and stepping through a shared mailbox, as a host drives them: every
    tick a reading, then messages handed over in a random order, a bounded number at a time."""

    def __init__(self, params: CamoParams, seed: int, continuous: bool = True) -> None:
        self.params = params
        self.random = random.Random(seed)
        self.projection = Projection(params.rows, params.cols, params.profile)
        self.mailbox = Mailbox(readers=params.count)
        robots = [
            StepProtocol(
                params,
                i,
                j,
                ProjectedSensor(self.projection, i, j),
                mailbox=self.mailbox,
            )
            for i in range(params.rows)
            for j in range(params.cols)
        ]
        self.robots = [r.watching() for r in robots] if continuous else robots
        self.hearers: dict[tuple[int, str], list[int]] = {}
        for p in self.robots:
            for sender, kind in p.listens_to():
                self.hearers.setdefault((sender, kind), []).append(p.id)
        self.watch = Watch(np.arange(params.count), params, WINDOW, THRESHOLD)
        self.rounds = [p.round for p in self.robots]
        self.sent: list = []
        self.woken: set[int] = set()
        self.results: dict[int, dict[int, tuple]] = {}  # round -> robot -> (pattern, p, state)
        self.noticed: dict[int, int] = {}  # round -> robot that noticed it first
        self.now = 0.0

    def post(self, robot: int, out) -> None:
        if out is not NOTHING:
            self.sent.extend(out.send)
        p = self.robots[robot]
        if p.round != self.rounds[robot]:
            self.rounds[robot] = p.round
            self.watch.reset([robot], self.projection.frames.get(p.round), p.round)
        if p.phase == DONE and p.round >= 0:
            core = p.core
            self.results.setdefault(p.round, {})[robot] = (core.pattern, core.p, core.state)

    def project(self, image: np.ndarray) -> int:
        number = self.projection.add(image)
        for k, p in enumerate(self.robots):
            self.post(k, p.background(self.now, number))
        return number

    def start(self) -> None:
        for k, p in enumerate(self.robots):
            self.post(k, p.start(self.now))

    def tick(self, deliveries: int = 400) -> None:
        self.now += 0.1
        idle = np.array([r < 0 for r in self.rounds])
        judged = self.watch.read(self.projection.latest, self.projection.newest, idle)
        for robot in judged.robots.tolist():
            before = self.robots[robot].round
            self.post(robot, self.robots[robot].notice(self.projection.newest, self.now))
            if self.robots[robot].round != before:
                self.noticed.setdefault(self.robots[robot].round, robot)
        for robot in judged.robots.tolist():
            round_ = self.robots[robot].round
            self.watch.reset([robot], self.projection.frames.get(round_), round_)
        for _ in range(deliveries):
            if not self.sent and not self.woken:
                break
            if self.sent:
                m = self.sent.pop(self.random.randrange(len(self.sent)))
                self.mailbox.put((m.round, m.kind, m.step), m.sender, m.value)
                self.woken.update(self.hearers.get((m.sender, m.kind), ()))
            else:
                robot = self.random.choice(sorted(self.woken))
                self.woken.discard(robot)
                self.post(robot, self.robots[robot].wake(self.now))

    def finished(self, round_: int) -> bool:
        return len(self.results.get(round_, {})) == self.params.count


def assert_round_like_sim(scene: Scene, round_: int, image: np.ndarray) -> None:
    params = scene.params
    grid = sense_image(image, params.rows, params.cols, params.profile)
    reference = simulate(params_of_round(params, round_), grid)
    for robot, (pattern, p, state) in scene.results[round_].items():
        i, j = divmod(robot, scene.params.cols)
        assert pattern == reference.selected[i, j] and state == reference.final[i, j]
        assert np.array_equal(p[:3], reference.p[i, j])


@pytest.mark.parametrize("rho", [0.0, 0.15])
def test_robots_start_their_own_rounds_on_each_changed_scene_each_equal_to_the_simulator(rho):
    params = CamoParams(rows=8, cols=8, rho_meas=rho, rho_comm=rho, seed=7)
    scene = Scene(params, seed=11)
    forest, desert = background("forest"), background("desert")
    scene.project(forest)
    scene.start()
    assert all(p.round == -1 and p.phase == DONE for p in scene.robots)  # no round yet
    for _ in range(100):
        scene.tick()
    first = scene.robots[0].round
    assert first == 0 and scene.finished(0)
    assert_round_like_sim(scene, 0, forest)
    for _ in range(40):  # the same scene, projected again and again: no new round
        scene.project(forest)
        scene.tick()
    assert {p.round for p in scene.robots} == {0}
    switched = scene.project(desert)
    for _ in range(200):
        scene.tick()
        scene.project(desert)
    rounds = {p.round for p in scene.robots}
    assert len(rounds) == 1
    latest = rounds.pop()
    assert latest >= switched
    assert scene.finished(latest) and scene.noticed.get(latest) is not None
    assert_round_like_sim(scene, latest, desert)


def test_a_scene_that_changes_as_a_round_starts_is_still_a_change_for_its_robots():
    # The reference is the round's frame read a window's worth of times, not the readings that
    # follow the join, which may be of the next scene already.
    watch = watch_of(4)
    forest, desert = np.full((1, 4), 70.0), np.full((1, 4), 180.0)
    for _ in range(2 * WINDOW):
        watch.read(forest, 0)
    watch.reset(np.arange(4), forest, 0)  # they joined the round of frame 0
    noticed = [len(watch.read(desert, 1 + k).robots) for k in range(WINDOW)]
    # As soon as all but one of a window's readings are of the new scene.
    assert noticed[: WINDOW - 2] == [0] * (WINDOW - 2) and noticed[WINDOW - 2] == 4


@pytest.mark.parametrize(
    "options",
    [
        {"levels": 4},
        {"threshold": "auto"},
        {"orientation": "any"},
        {"profile": "droplet"},
    ],
    ids=["levels", "threshold-auto", "orientation-any", "droplet"],
)
def test_continuous_rounds_equal_the_simulator_with_the_options_beyond_the_paper(options):
    params = CamoParams.from_options(rows=8, cols=8, rho_comm=0.1, rho_meas=0.1, seed=3, **options)
    scene = Scene(params, seed=5)
    scene.project(background("desert"))
    scene.start()
    for _ in range(100):
        scene.tick()
    assert scene.finished(0)
    assert_round_like_sim(scene, 0, background("desert"))
    leopard = background("leopard")
    for _ in range(150):
        scene.project(leopard)
        scene.tick()
    (latest,) = {p.round for p in scene.robots}
    assert latest > 0 and scene.finished(latest)
    assert_round_like_sim(scene, latest, leopard)


def test_a_newer_round_supersedes_an_unfinished_one():
    params = CamoParams(rows=8, cols=8, consensus_steps=200)
    scene = Scene(params, seed=3)
    scene.project(background("forest"))
    scene.start()
    while not any(p.round == 0 for p in scene.robots):
        scene.tick()
    for _ in range(5):  # round 0 under way, far from done
        scene.tick(deliveries=50)
    assert not scene.finished(0)
    leopard = background("leopard")
    for _ in range(300):
        scene.project(leopard)
        scene.tick()
    rounds = {p.round for p in scene.robots}
    assert len(rounds) == 1
    latest = rounds.pop()
    assert latest > 0
    assert scene.finished(latest) and not scene.finished(0)
    assert_round_like_sim(scene, latest, leopard)


def test_without_continuous_a_new_frame_starts_the_next_round_once_done():
    params = CamoParams(rows=8, cols=8)
    scene = Scene(params, seed=2, continuous=False)
    scene.project(background("forest"))
    scene.start()
    for _ in range(50):
        scene.tick()
    assert scene.finished(0) and all(p.phase == DONE for p in scene.robots)
    scene.project(background("desert"))
    for _ in range(50):
        scene.tick()
    assert scene.finished(1) and scene.robots[5].round == 1 and not scene.noticed
    assert_round_like_sim(scene, 1, background("desert"))


def test_a_robot_joining_a_round_its_process_has_no_frame_for_yet_waits_for_it():
    params = CamoParams(rows=1, cols=2)
    projection = Projection(1, 2, "paper")
    projection.add(np.full((4, 4), 30, np.uint8))
    robot = StepProtocol(params, 0, 0, ProjectedSensor(projection, 0, 0)).watching()
    robot.start(0.0)
    robot.deliver(Message("hello", 1, 5, 0, (0, 1)), 0.1)  # a neighbour in round 5 (frame 5)
    assert (robot.round, robot.phase) == (5, SENSING)  # its hello says who it heard
    assert robot.hardware_wait and np.isnan(robot.core.sensed)  # frame 5 has not come
    projection.add(np.full((4, 4), 200, np.uint8), 5)
    robot.tick(0.2)
    assert robot.core.sensed == 200.0
