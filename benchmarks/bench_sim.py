"""Simulator-step and neighbour-query benchmarks.

The step is timed on a 350 x 350 grid (35 m at 10 cells/m, the size of the
DFCOA S1 map) with 4 unicycles, each with a 120-beam LiDAR (range 10 m), under
``goto_slot`` (made to take the scan, :func:`scanning`). The same-run
reference is the identical simulation with the LiDAR replaced by
vectorised-numpy ray sampling (``bench_lidar``); another row times the step
without the LiDAR, as the simulator runs ``goto_slot`` itself.
"""

from __future__ import annotations

import time

import numpy as np

from benchmarks.bench_lidar import make_grid, numpy_sampling_scan
from benchmarks.timing import blocks, interleave, print_rows, row, time_calls
from dfcoa_opt.control.registry import make_controller
from dfcoa_opt.scenario.loader import scenario_from_dict
from dfcoa_opt.sim import neighbours
from dfcoa_opt.sim.simulator import Simulator
from dfcoa_opt.world.lidar import LaserScan
from dfcoa_opt.world.robots.models import ActuatedUnicycle, RobotState, Unicycle
from dfcoa_opt.world.robots.spec import RobotSpec

#: Whole runs per simulator, taken in turns (split into REPS blocks for the ratios).
RUNS = 10


def scanning(controller_id: str) -> object:
    """The controller, made to take the scan (``uses_scan = True``) so that the LiDAR runs.

    The simulator skips the LiDAR for a controller that reads no scan (such as
    ``goto_slot``); the step benchmarks time the step *with* the LiDAR, as the
    issue's row (d) and its ir-sim peer do.
    """
    ctrl = make_controller(controller_id)
    ctrl.uses_scan = True  # type: ignore[attr-defined]
    return ctrl


def _scenario():
    grid = make_grid()
    ascii_map = "\n".join("".join("#" if c else "." for c in r) for r in grid.occupied[::-1])
    rows, cols = np.nonzero(~grid.inflate(1.5).occupied)
    centres = grid.cell_centers()[rows, cols]
    x0, x1, y0, y1 = grid.extent
    inside = ((centres[:, 0] >= x0 + 1.5) & (centres[:, 0] <= x1 - 1.5)  # the formation fits
              & (centres[:, 1] >= y0 + 1.5) & (centres[:, 1] <= y1 - 1.5))
    start = centres[np.flatnonzero(inside)[0]]
    return scenario_from_dict({
        "t_max": 30.0, "dt": 0.1,
        "world": {"map_ascii": ascii_map, "resolution": 10.0},
        "team": {"n": 4}, "formation": {"width": 1.0, "length": 1.0},
        "leader": {"start": list(start), "goal": [34.0, 34.0], "speed": 0.3},
        "sensors": {"lidar": {"beams": 120, "range_max": 10.0}},
    }, "<bench>")


def _per_step_us(*sims: Simulator) -> list[np.ndarray]:
    """Per-step times (us) of whole runs, the simulators taking turns (drift hits all alike)."""
    out = [np.empty(RUNS) for _ in sims]
    for sim in sims:
        sim.run()  # warm-up (numba compile, caches)
    for k in range(RUNS):
        for sim, times in zip(sims, out, strict=True):
            log = sim.run()
            times[k] = log.meta["wall_time"] / log.meta["steps"] * 1e6
    return out


#: ir-sim world of the peer row (issue 7 row d): 4 differential-drive robots with a
#: 120-beam, 10 m, 360-degree lidar2d in a 35 m square with 6 discs, driving to goals.
IRSIM_WORLD = {
    "world": {"height": 35, "width": 35, "step_time": 0.1, "sample_time": 0.1,
              "collision_mode": "unobstructed", "control_mode": "auto"},
    "robot": [{"number": 4, "distribution": {"name": "manual"},
               "kinematics": {"name": "diff"}, "shape": {"name": "circle", "radius": 0.2},
               "state": [[2, 2, 0], [2, 4, 0], [4, 2, 0], [4, 4, 0]],
               "goal": [[30, 30, 0], [30, 32, 0], [32, 30, 0], [32, 32, 0]],
               "behavior": {"name": "dash"},
               "sensors": [{"name": "lidar2d", "range_min": 0, "range_max": 10,
                            "angle_range": 2 * np.pi, "number": 120}]}],
    "obstacle": [{"number": 6, "distribution": {"name": "manual"},
                  "shape": [{"name": "circle", "radius": 0.5}],
                  "state": [[10, 10, 0], [12, 20, 0], [20, 12, 0], [25, 25, 0], [8, 25, 0],
                            [25, 8, 0]]}],
}


def irsim_step_us(steps: int = 200) -> list[np.ndarray] | None:
    """Per-step times (us) of ir-sim's headless ``env.step()``; None if ir-sim is missing.

    ``steps`` steps in :data:`~benchmarks.timing.REPS` blocks, one block per
    repetition (the peer runs in its own process state, so it is timed in
    blocks after ours rather than call for call).

    ir-sim is the peer of issue 7 row (d) (``pip install ir-sim``, or the
    ``bench`` extra that ``make bench`` installs). Its world is not ours (discs
    instead of an occupancy grid), but the work per step is the same: 4 robots
    moved and 4 x 120 beams cast.
    """
    try:
        import irsim
        import yaml
    except ImportError:
        print("ir-sim is not installed: its peer row is left out (pip install ir-sim)")
        return None
    import logging
    import tempfile
    from pathlib import Path

    logging.disable(logging.WARNING)
    with tempfile.TemporaryDirectory() as tmp:
        world = Path(tmp) / "bench_world.yaml"
        world.write_text(yaml.safe_dump(IRSIM_WORLD))
        env = irsim.make(str(world), headless=True, log_level="ERROR")
        for _ in range(20):
            env.step()
        out = blocks(time_calls(lambda k: env.step(), steps))
    logging.disable(logging.NOTSET)
    return out


def model_rows() -> list[dict]:
    """The actuated model's step per robot against the kinematic unicycle's (same process).

    Both step the same poses and commands (random, some beyond the wheel limit);
    the actuated model with a motor lag, an acceleration limit and its default
    4 substeps. Times are per robot-step (the call's time over N).
    """
    rng = np.random.default_rng(1)
    base = dict(wheel_radius=0.033, track_width=0.16, wheel_speed_max=6.4)
    kin = Unicycle(RobotSpec(**base))
    act = ActuatedUnicycle(RobotSpec(**base, dynamics="actuated", wheel_accel_max=2.5,
                                     motor_time_constant=0.05))
    rows = []
    for n in (4, 1024):
        pose = rng.uniform(-5, 5, (n, 3))
        cmd = rng.uniform(-1, 1, (n, 2))
        st = RobotState(pose, np.zeros((n, 2)), np.zeros((n, 2)),
                        rng.uniform(-6, 6, (n, 2)))
        t = interleave({"act": (lambda k, s=st, c=cmd: act.step(s, c, 0.1), 400),
                        "kin": (lambda k, s=st, c=cmd: kin.step(s, c, 0.1), 400)})
        per = {k: [a / n for a in v] for k, v in t.items()}
        rows.append(row(f"robot model step per robot, N={n}, actuated (lag, accel limit, "
                        "4 substeps)", per["act"], "kinematic unicycle step", per["kin"]))
    return rows


def run() -> list[dict]:
    """Time the simulator step and the neighbour query; one dict per row."""
    sc = _scenario()
    ours, skipped = _per_step_us(Simulator(sc, scanning("goto_slot")),
                                 Simulator(sc, make_controller("goto_slot")))
    ref_sim = Simulator(sc, scanning("goto_slot"))
    grid, lidar = sc.world.grid, ref_sim.lidar

    def numpy_lidar(poses, *args, **kwargs):
        ang = lidar.scan(poses[:1]).angles
        r = np.array([numpy_sampling_scan(grid, p, ang, 10.0) for p in poses])
        return LaserScan(ang[0], ang[1] - ang[0], 0.0, 10.0, r)

    ref_sim.lidar = type("NumpyLidar", (), {"scan": staticmethod(numpy_lidar)})()
    (ref,) = _per_step_us(ref_sim)
    ours, skipped, ref = blocks(ours), blocks(skipped), blocks(ref)
    rows = [row("simulator step, 4 unicycles with 120-beam LiDAR, 350x350 grid", ours,
                "same step with numpy-sampling LiDAR", ref)]
    rows.append(row("simulator step, 4 unicycles, LiDAR skipped (goto_slot reads no scan)",
                    skipped, "same step with the LiDAR", ours))
    peer = irsim_step_us()
    if peer is not None:
        rows.append(row("simulator step, 4 unicycles with 120-beam LiDAR, 350x350 grid", ours,
                        "ir-sim headless step, 4 diff robots, 120-beam lidar2d, 6 discs", peer))
    rows += model_rows()
    rng = np.random.default_rng(0)
    for n in (16, 32, 48, 64, 128, 256):
        pts = rng.uniform(0, np.sqrt(n) * 2.0, (n, 2))
        saved = neighbours.KERNEL_MAX

        def query(kernel_max: int, p: np.ndarray = pts) -> object:
            neighbours.KERNEL_MAX = kernel_max
            return neighbours.proximity(p, 10.0, 10, 0.4)

        try:
            t = interleave({"dense": (lambda k: query(10**9), 60),
                            "tree": (lambda k: query(0), 60)})
        finally:
            neighbours.KERNEL_MAX = saved
        rows.append(row(f"neighbour query N={n}, compiled all-pairs loop", t["dense"],
                        "cKDTree", t["tree"]))
    return rows


if __name__ == "__main__":
    t0 = time.perf_counter()
    print_rows(run())
    print(f"{time.perf_counter() - t0:.1f} s")
