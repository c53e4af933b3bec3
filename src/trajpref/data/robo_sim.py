"""robo-sim: a small vectorised simulator of the "Robo" scenario.

Scenario (as described in the paper): two robots walk together while a third
robot approaches them and adjusts its path to avoid a collision. Episodes have
8 history frames and 12 future frames at 0.5 s per frame, 3 agents per scene.

The official training split is not public, so this module generates training
data of our own. The model was written from scratch after studying the
official *validation* split (see ``docs/robo_sim.md``). All three robots are
unicycles (heading + speed) driven by the same kind of controller, which is
updated once per 0.5 s frame (zero-order hold; the motion itself is integrated
at ``substeps`` internal steps per frame):

* the heading error to the wanted direction is measured counter-clockwise,
  except that clockwise corrections up to ``cw_tolerance`` are allowed. Small
  errors are corrected proportionally at cruise speed; larger ones are turned
  through counter-clockwise at the full turn rate ("bang-bang") and, for the
  follower and the approacher, at a lower turning speed. Because the turn is
  done in whole frames it overshoots, and an overshoot to the clockwise side
  triggers another full loop: this reproduces the loops of the real robots.
* agent 0, the **leader**, shuttles between a goal on the left wall (high)
  and one on the right wall (low); at each wall it turns back, and as its
  position is clipped to the arena it slides along the wall while turning.
* agent 1, the **follower**, pursues the leader's current position and
  stands still while it is closer than ``follower_stop_dist``.
* agent 2, the **approacher**, starts near one horizontal edge (facing a
  random direction) and crosses to a goal near the opposite edge. It avoids
  the pair with an anticipatory social-force rule of ours: for each pair
  member it predicts the closest point of approach (constant relative
  velocity, bounded horizon) and is pushed away from that predicted point
  with a strength that decays exponentially with the predicted separation.
* a recorded run starts when the approacher starts and ends when it reaches
  its goal; an episode is a 20-frame window starting at a random frame of the
  run (the official files are stride-1 windows over such runs). Frame
  intervals are random around 0.5 s (shared by the three robots) and the
  commanded speeds carry a little noise, which gives the frame-to-frame speed
  fluctuations of the real recordings.

Everything is vectorised over episodes with numpy (episodes are processed in
chunks to bound memory); the only Python loop is over internal time steps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from trajpref.errors import ConfigError

FRAME_DT = 0.5
"""Seconds between two recorded frames."""
N_HISTORY = 8
"""Number of history (observed) frames."""
N_FUTURE = 12
"""Number of future (predicted) frames."""
N_FRAMES = N_HISTORY + N_FUTURE
"""Recorded frames per episode."""
N_AGENTS = 3
"""Agents per scene: 0 = leader, 1 = follower, 2 = approacher."""

_CHUNK = 4096  # episodes simulated at once (bounds memory)
_N_GOALS = 16  # pre-drawn goals per agent and episode (cycled)


@dataclass
class RoboSimConfig:
    """Parameters of robo-sim. Defaults are tuned on the official Robo val set."""

    arena_size: float = 11.0889
    """Side of the square arena [0, arena_size]^2 in metres; positions are clipped to it."""

    substeps: int = 5
    """Internal integration steps per 0.5 s frame (internal dt = 0.5 / substeps)."""

    max_start_frame: int = 30
    """Largest frame of a run at which the recorded 20-frame window may start."""

    leader_speed: float = 0.89
    """Cruise speed of the leader (agent 0) in m/s; it does not slow down to turn."""

    leader_turn_rate: float = 0.65
    """Turn rate of the leader in rad/s."""

    leader_left_y: tuple[float, float] = (5.5, 9.2)
    """Range (low, high) of the y coordinate of the leader's goals on the left wall (x = 0)."""

    leader_right_y: tuple[float, float] = (0.3, 2.3)
    """Range (low, high) of the y coordinate of the leader's goals on the right wall."""

    leader_goal_tol: float = 0.4
    """The leader turns back once this close (m) to its goal or when it touches the goal's wall."""

    follower_speed: float = 0.79
    """Cruise speed of the follower (agent 1) in m/s."""

    follower_turn_speed: float = 0.38
    """Speed of the follower while it turns at full rate, m/s."""

    follower_turn_rate: float = 1.47
    """Turn rate of the follower in rad/s."""

    follower_stop_dist: float = 0.8
    """The follower stands still while closer than this to the leader (m)."""

    follower_start_dist: tuple[float, float] = (1.0, 3.5)
    """Range (low, high) of the initial distance of the follower behind the leader (m)."""

    approacher_speed: float = 0.58
    """Cruise speed of the approacher (agent 2) in m/s."""

    approacher_turn_speed: float = 0.30
    """Speed of the approacher while it turns at full rate, m/s."""

    approacher_turn_rate: float = 0.8
    """Turn rate of the approacher in rad/s."""

    approacher_edge_y: tuple[float, float] = (1.2, 10.3)
    """y of the two horizontal lines on which the approacher starts (+-0.15 m) its crossing (m)."""

    approacher_start_spread: float = 0.7
    """Initial heading of the approacher: facing out of the arena +- up to this angle (rad)."""

    approacher_goal_inset: float = 0.4
    """The approacher's goal lies this far (m) inside the opposite start line."""

    approacher_x: tuple[float, float] = (0.6, 10.2)
    """Range (low, high) of the x coordinate of the approacher's start and goal (m)."""

    approacher_goal_x_std: float = 0.7
    """Std (m) of the goal's x around the start mirrored through the arena centre."""

    approacher_goal_tol: float = 0.3
    """The approacher has reached a waypoint / its goal when less than this (m) short of it along
    its leg (the recorded run ends at the goal)."""

    turn_threshold: float = 0.35
    """Counter-clockwise heading error (rad) above which a robot turns at its full rate."""

    cw_tolerance: float = 0.07
    """Largest clockwise heading error (rad) that leader and follower correct clockwise;
    larger ones are turned through counter-clockwise (a loop)."""

    approacher_cw_tolerance: float = math.pi
    """Same as ``cw_tolerance`` for the approacher (pi: it always turns the shorter way)."""

    accel: float = 1.0
    """Maximum acceleration (and deceleration) of the robots in m/s^2."""

    avoid_strength: float = 0.6
    """Strength (m/s) of the approacher's collision-avoidance push; 0 switches avoidance off."""

    avoid_range: float = 0.6
    """Length scale (m) over which the avoidance push decays with the predicted separation."""

    avoid_radius: float = 0.3
    """Predicted separation (m) below which the avoidance push has its full strength."""

    avoid_horizon: float = 4.0
    """Look-ahead horizon (s) of the approacher's closest-approach prediction."""

    heading_noise: float = 0.08
    """Std (rad) of per-frame noise on the direction wanted by the approacher (path wobble)."""

    speed_run_std: float = 0.03
    """Relative std of a per-episode, per-robot factor on the cruise and turning speeds."""

    speed_noise: float = 0.03
    """Relative std of a per-frame, per-robot random factor on the commanded speed."""

    frame_interval_std: float = 0.07
    """Relative std of the (shared) recording interval around 0.5 s."""

    frame_interval_tail_prob: float = 0.12
    """Probability that a recording interval has an extra, large deviation."""

    frame_interval_tail_std: float = 0.3
    """Relative std of that extra deviation (intervals are clipped to [0.2, 1.8] x 0.5 s)."""

    def __post_init__(self) -> None:
        def number(name: str, lo: float, hi: float, lo_open: bool = False) -> None:
            value = getattr(self, name)
            ok = (
                isinstance(value, (int, float))
                and not isinstance(value, bool)
                and math.isfinite(value)
            )
            ok = ok and (value > lo if lo_open else value >= lo) and value <= hi
            if not ok:
                bound = f"{'>' if lo_open else '>='} {lo} and <= {hi}"
                raise ConfigError(
                    f"RoboSimConfig.{name} must be a finite number {bound}, got {value!r}"
                )

        def integer(name: str, lo: int, hi: int) -> None:
            value = getattr(self, name)
            if not (
                isinstance(value, (int, np.integer))
                and not isinstance(value, bool)
                and lo <= value <= hi
            ):
                raise ConfigError(
                    f"RoboSimConfig.{name} must be an int in [{lo}, {hi}], got {value!r}"
                )

        def interval(name: str, lo: float, hi: float) -> None:
            value = getattr(self, name)
            try:
                a, b = (float(v) for v in value)
            except (TypeError, ValueError):
                raise ConfigError(
                    f"RoboSimConfig.{name} must be a (low, high) pair, got {value!r}"
                ) from None
            if not (math.isfinite(a) and math.isfinite(b) and lo <= a <= b <= hi):
                raise ConfigError(
                    f"RoboSimConfig.{name} must satisfy {lo} <= low <= high <= {hi}, got {value!r}"
                )

        inf = math.inf
        number("arena_size", 1.0, 1e4)
        integer("substeps", 1, 100)
        integer("max_start_frame", 0, 1000)
        for name in ("leader_speed", "follower_speed", "approacher_speed"):
            number(name, 0.0, 10.0, lo_open=True)
        for name in ("follower_turn_speed", "approacher_turn_speed"):
            number(name, 0.0, 10.0)
        for name in ("leader_turn_rate", "follower_turn_rate", "approacher_turn_rate"):
            number(name, 0.0, 4 * math.pi, lo_open=True)
        for name in (
            "leader_goal_tol",
            "approacher_goal_tol",
            "accel",
            "avoid_range",
            "avoid_horizon",
        ):
            number(name, 0.0, inf, lo_open=True)
        for name in ("follower_stop_dist", "avoid_strength", "avoid_radius"):
            number(name, 0.0, inf)
        number("turn_threshold", 0.0, math.pi)
        number("cw_tolerance", 0.0, math.pi)
        number("approacher_cw_tolerance", 0.0, math.pi)
        number("heading_noise", 0.0, 1.0)
        for name in (
            "speed_run_std",
            "speed_noise",
            "frame_interval_std",
            "frame_interval_tail_std",
        ):
            number(name, 0.0, 0.5)
        number("frame_interval_tail_prob", 0.0, 1.0)
        if self.follower_turn_speed > self.follower_speed:
            raise ConfigError("RoboSimConfig.follower_turn_speed must be <= follower_speed")
        if self.approacher_turn_speed > self.approacher_speed:
            raise ConfigError("RoboSimConfig.approacher_turn_speed must be <= approacher_speed")
        size = self.arena_size
        interval("leader_left_y", 0.0, size)
        interval("leader_right_y", 0.0, size)
        interval("follower_start_dist", 0.0, size)
        interval("approacher_edge_y", 0.0, size)
        interval("approacher_x", 0.0, size)
        number("approacher_goal_x_std", 0.0, size)
        number("approacher_start_spread", 0.0, math.pi)
        number("approacher_goal_inset", 0.0, size)
        gap = self.approacher_edge_y[1] - self.approacher_edge_y[0] - 2 * self.approacher_goal_inset
        if gap <= 2 * self.approacher_goal_tol + 0.3:
            raise ConfigError(
                "RoboSimConfig.approacher_edge_y lines are too close for "
                "approacher_goal_inset / approacher_goal_tol"
            )

    def to_dict(self) -> dict[str, object]:
        """Return the configuration as a plain dict (for logging)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


def _wrap(angle: np.ndarray) -> np.ndarray:
    """Wrap angles to [-pi, pi)."""
    return (angle + np.pi) % (2 * np.pi) - np.pi


def _unit(heading: np.ndarray) -> np.ndarray:
    """Unit vectors [...,D] for headings [...]."""
    return np.stack([np.cos(heading), np.sin(heading)], axis=-1)


def _avoidance(
    own_pos: np.ndarray,
    own_vel: np.ndarray,
    others: list[tuple[np.ndarray, np.ndarray]],
    cfg: RoboSimConfig,
) -> np.ndarray:
    """Anticipatory avoidance push [E,D] (m/s) on a robot at own_pos [E,D] with intent own_vel."""
    push = np.zeros_like(own_pos)  # E,D
    for other_pos, other_vel in others:
        rel = other_pos - own_pos  # E,D
        rel_vel = other_vel - own_vel  # E,D
        rv2 = np.maximum((rel_vel**2).sum(-1), 1e-9)  # E
        t_cpa = np.clip(-(rel * rel_vel).sum(-1) / rv2, 0.0, cfg.avoid_horizon)  # E
        sep = rel + rel_vel * t_cpa[:, None]  # E,D, predicted separation at closest approach
        sep_d = np.maximum(np.hypot(sep[:, 0], sep[:, 1]), 1e-6)  # E
        mag = cfg.avoid_strength * np.exp(
            -np.maximum(sep_d - cfg.avoid_radius, 0.0) / cfg.avoid_range
        )  # E
        mag = mag * (1.0 - 0.5 * t_cpa / cfg.avoid_horizon)  # E, sooner -> stronger
        push = push - mag[:, None] * sep / sep_d[:, None]
    return push


def _control(
    want: np.ndarray,
    heading: np.ndarray,
    cruise: np.ndarray,
    turn_speed: np.ndarray,
    turn_rate: float,
    tol: float,
    cfg: RoboSimConfig,
) -> tuple[np.ndarray, np.ndarray]:
    """One frame of the shared heading controller: (turn rate [E] in rad/s, target speed [E])."""
    err = (want - heading + tol) % (2 * np.pi) - tol  # E, in [-tol, 2 pi - tol): CCW preferred
    full = np.abs(err) > cfg.turn_threshold  # E
    rate = np.where(
        full, np.sign(err) * turn_rate, np.clip(err / FRAME_DT, -turn_rate, turn_rate)
    )  # E
    return rate, np.where(full, turn_speed, cruise)


def _simulate_chunk(n: int, rng: np.random.Generator, cfg: RoboSimConfig) -> np.ndarray:
    """Simulate ``n`` episodes and return the recorded windows [E,P,T,D] (float64)."""
    size = cfg.arena_size
    sub = cfg.substeps
    dt = FRAME_DT / sub
    n_run_frames = (
        cfg.max_start_frame + N_FRAMES + 4
    )  # frames simulated per run (slack for timing noise)
    ng = _N_GOALS

    # ---- all randomness is drawn up front, in a fixed order, so that changing a
    # ---- behaviour parameter (e.g. avoid_strength=0) keeps the same random draws.
    u_leader_pos = rng.uniform(0.0, 1.0, size=(n, 2))  # E,D
    u_leader_side = rng.integers(0, 2, size=n)  # E
    u_goal_y = rng.uniform(0.0, 1.0, size=(n, ng))  # E,G
    u_follow = rng.uniform(0.0, 1.0, size=(n, 2))  # E,2 (distance, lateral offset)
    u_app_side = rng.integers(0, 2, size=n)  # E
    u_app_x = rng.uniform(0.0, 1.0, size=n)  # E
    n_app_x = rng.standard_normal((n, ng))  # E,G
    u_app_y = rng.uniform(-0.15, 0.15, size=(n, ng + 1))  # E,G+1
    u_app_heading = rng.uniform(-1.0, 1.0, size=n)  # E
    run_factor = 1.0 + cfg.speed_run_std * rng.standard_normal((n, N_AGENTS))  # E,P
    frame_factor = 1.0 + cfg.speed_noise * rng.standard_normal((n, N_AGENTS, n_run_frames))  # E,P,F
    interval = 1.0 + cfg.frame_interval_std * rng.standard_normal((n, N_FRAMES - 1))  # E,T-1
    tail = rng.uniform(0.0, 1.0, size=(n, N_FRAMES - 1)) < cfg.frame_interval_tail_prob  # E,T-1
    interval = interval + tail * cfg.frame_interval_tail_std * rng.standard_normal(
        (n, N_FRAMES - 1)
    )
    interval = FRAME_DT * np.clip(interval, 0.2, 1.8)  # E,T-1, seconds
    u_start = rng.uniform(0.0, 1.0, size=n)  # E
    want_noise = cfg.heading_noise * rng.standard_normal((n, n_run_frames))  # E,F (approacher)

    e_idx = np.arange(n)
    speed_scale = run_factor[:, :, None] * frame_factor  # E,P,F

    # ---- leader (agent 0)
    side = u_leader_side.astype(np.float64)  # E, 1 = goal on the right wall, 0 = left wall
    lo_l, hi_l = cfg.leader_left_y
    lo_r, hi_r = cfg.leader_right_y
    goal_y_left = lo_l + (hi_l - lo_l) * u_goal_y  # E,G
    goal_y_right = lo_r + (hi_r - lo_r) * u_goal_y  # E,G
    n_switch = np.zeros(n, dtype=np.int64)  # E
    lead_goal = np.stack(
        [side * size, np.where(side > 0, goal_y_right[:, 0], goal_y_left[:, 0])], -1
    )  # E,D
    # start somewhere on the straight shuttle line between the previous goal and the current one
    prev_goal = np.stack(
        [(1.0 - side) * size, lo_l + (hi_l - lo_l) * u_leader_pos[:, 1]], -1
    )  # E,D
    prev_goal[:, 1] = np.where(side > 0, prev_goal[:, 1], lo_r + (hi_r - lo_r) * u_leader_pos[:, 1])
    lead_pos = prev_goal + (0.05 + 0.9 * u_leader_pos[:, :1]) * (lead_goal - prev_goal)  # E,D
    to_goal = lead_goal - lead_pos  # E,D
    lead_heading = np.arctan2(to_goal[:, 1], to_goal[:, 0])  # E
    lead_speed = cfg.leader_speed * run_factor[:, 0]  # E

    # ---- follower (agent 1): behind the leader, with a small lateral offset
    lo_f, hi_f = cfg.follower_start_dist
    back = -_unit(lead_heading)  # E,D
    lateral = np.stack([-back[:, 1], back[:, 0]], axis=-1)  # E,D
    fol_pos = (
        lead_pos
        + (lo_f + (hi_f - lo_f) * u_follow[:, :1]) * back
        + (u_follow[:, 1:] - 0.5) * lateral
    )  # E,D
    fol_pos = np.clip(fol_pos, 0.2, size - 0.2)
    d = lead_pos - fol_pos  # E,D
    fol_heading = np.arctan2(d[:, 1], d[:, 0])  # E
    fol_speed = cfg.follower_speed * run_factor[:, 1]  # E

    # ---- approacher (agent 2): from near one horizontal edge to near the other
    y_lo, y_hi = cfg.approacher_edge_y
    x_lo, x_hi = cfg.approacher_x
    # crossing j goes from end point j to end point j + 1, through an "8-connected grid" waypoint:
    # a 45 degree diagonal leg first, then an axis-aligned one
    ends = np.empty((n, ng + 1, 2))  # E,G+1,D
    ends[:, 0, 0] = x_lo + (x_hi - x_lo) * u_app_x
    for j in range(ng):
        ends[:, j + 1, 0] = np.clip(
            size - ends[:, j, 0] + cfg.approacher_goal_x_std * n_app_x[:, j], x_lo, x_hi
        )
    line = (u_app_side[:, None] + np.arange(ng + 1)[None, :]) % 2  # E,G+1, alternating edges
    ends[:, :, 1] = np.where(line == 0, y_lo, y_hi) + u_app_y
    ends[:, 1:, 1] += np.where(
        line[:, 1:] == 0, cfg.approacher_goal_inset, -cfg.approacher_goal_inset
    )
    delta = ends[:, 1:] - ends[:, :-1]  # E,G,D
    diag = np.minimum(np.abs(delta[..., 0]), np.abs(delta[..., 1]))  # E,G
    waypoint = ends[:, :-1] + np.sign(delta) * diag[..., None]  # E,G,D
    targets = np.stack([waypoint, ends[:, 1:]], axis=2).reshape(n, 2 * ng, 2)  # E,2G,D
    legs = targets - np.concatenate([ends[:, :1], targets[:, :-1]], axis=1)  # E,2G,D
    legs = (
        legs / np.maximum(np.hypot(legs[..., 0], legs[..., 1]), 1e-9)[..., None]
    )  # unit (or 0 if empty)
    app_pos = ends[:, 0].copy()  # E,D
    app_k = np.zeros(n, dtype=np.int64)  # E, index of the current target (odd = goal)
    # it starts facing out of the arena (towards its start edge) and first has to turn round
    app_heading = (
        np.where(line[:, 0] == 0, -np.pi / 2, np.pi / 2)
        + cfg.approacher_start_spread * u_app_heading
    )  # E
    app_speed = np.zeros(n)  # E
    reach_frame = np.full(
        n, n_run_frames, dtype=np.int64
    )  # E, frame at which the first goal is reached

    n_steps = n_run_frames * sub
    traj = np.empty((n, N_AGENTS, n_steps + 1, 2))  # E,P,S,D
    traj[:, 0, 0] = lead_pos
    traj[:, 1, 0] = fol_pos
    traj[:, 2, 0] = app_pos
    max_dv = cfg.accel * dt

    for frame in range(n_run_frames):
        scale = speed_scale[:, :, frame]  # E,P

        # ---- decisions, once per frame (zero-order hold)
        # leader: turn back at the goal's wall
        at_wall = np.where(side > 0, lead_pos[:, 0] >= size - 1e-9, lead_pos[:, 0] <= 1e-9)  # E
        switch = at_wall | (np.hypot(*(lead_goal - lead_pos).T) < cfg.leader_goal_tol)  # E
        if switch.any():
            n_switch = n_switch + switch
            side = np.where(switch, 1.0 - side, side)
            g = n_switch % ng  # E
            gy = np.where(side > 0, goal_y_right[e_idx, g], goal_y_left[e_idx, g])  # E
            lead_goal = np.where(switch[:, None], np.stack([side * size, gy], axis=-1), lead_goal)
        to_goal = lead_goal - lead_pos  # E,D
        cruise = cfg.leader_speed * scale[:, 0]  # E
        lead_rate, lead_target = _control(
            np.arctan2(to_goal[:, 1], to_goal[:, 0]),
            lead_heading,
            cruise,
            cruise,
            cfg.leader_turn_rate,
            cfg.cw_tolerance,
            cfg,
        )

        # follower: pursue the leader, stop when close
        d = lead_pos - fol_pos  # E,D
        fol_rate, fol_target = _control(
            np.arctan2(d[:, 1], d[:, 0]),
            fol_heading,
            cfg.follower_speed * scale[:, 1],
            cfg.follower_turn_speed * scale[:, 1],
            cfg.follower_turn_rate,
            cfg.cw_tolerance,
            cfg,
        )
        stop = np.hypot(d[:, 0], d[:, 1]) < cfg.follower_stop_dist  # E
        fol_rate = np.where(stop, 0.0, fol_rate)
        fol_target = np.where(stop, 0.0, fol_target)

        # approacher: goal seeking + anticipatory avoidance of the pair
        to_goal = targets[e_idx, app_k] - app_pos  # E,D
        # a target is reached once the robot is near the line across its leg through it
        reached = (to_goal * legs[e_idx, app_k]).sum(-1) < cfg.approacher_goal_tol  # E
        if reached.any():
            first_goal = reached & (app_k == 1) & (reach_frame == n_run_frames)  # E
            reach_frame = np.where(first_goal, frame, reach_frame)
            app_k = np.minimum(app_k + reached, 2 * ng - 1)
            to_goal = targets[e_idx, app_k] - app_pos
        desired = (
            cfg.approacher_speed * to_goal / np.maximum(np.hypot(*to_goal.T), 1e-9)[:, None]
        )  # E,D
        if cfg.avoid_strength > 0:
            others = [
                (lead_pos, lead_speed[:, None] * _unit(lead_heading)),
                (fol_pos, fol_speed[:, None] * _unit(fol_heading)),
            ]
            desired = desired + _avoidance(app_pos, desired, others, cfg)
        app_rate, app_target = _control(
            np.arctan2(desired[:, 1], desired[:, 0]) + want_noise[:, frame],
            app_heading,
            cfg.approacher_speed * scale[:, 2],
            cfg.approacher_turn_speed * scale[:, 2],
            cfg.approacher_turn_rate,
            cfg.approacher_cw_tolerance,
            cfg,
        )

        # ---- integrate the frame
        for k in range(sub):
            lead_heading = lead_heading + lead_rate * dt
            lead_speed = lead_speed + np.clip(lead_target - lead_speed, -max_dv, max_dv)
            lead_pos = np.clip(
                lead_pos + (lead_speed * dt)[:, None] * _unit(lead_heading), 0.0, size
            )
            fol_heading = fol_heading + fol_rate * dt
            fol_speed = fol_speed + np.clip(fol_target - fol_speed, -max_dv, max_dv)
            fol_pos = np.clip(fol_pos + (fol_speed * dt)[:, None] * _unit(fol_heading), 0.0, size)
            app_heading = app_heading + app_rate * dt
            app_speed = app_speed + np.clip(app_target - app_speed, -max_dv, max_dv)
            app_pos = np.clip(app_pos + (app_speed * dt)[:, None] * _unit(app_heading), 0.0, size)
            s = frame * sub + k + 1
            traj[:, 0, s] = lead_pos
            traj[:, 1, s] = fol_pos
            traj[:, 2, s] = app_pos
        lead_heading = _wrap(lead_heading)
        fol_heading = _wrap(fol_heading)
        app_heading = _wrap(app_heading)

    # ---- the recorded window must end before the approacher reaches its goal
    last_start = np.clip(reach_frame - N_FRAMES, 0, cfg.max_start_frame)  # E
    start = np.floor(u_start * (last_start + 1)).astype(np.int64)  # E
    times = start[:, None] * FRAME_DT + np.concatenate(
        [np.zeros((n, 1)), np.cumsum(interval, axis=1)], axis=1
    )  # E,T
    t = np.clip(times / dt, 0.0, n_steps)  # E,T in internal steps
    i0 = np.minimum(np.floor(t).astype(np.int64), n_steps - 1)  # E,T
    w = (t - i0)[:, None, :, None]  # E,1,T,1
    ei = e_idx[:, None, None]  # E,1,1
    pi = np.arange(N_AGENTS)[None, :, None]  # 1,P,1
    p0 = traj[ei, pi, i0[:, None, :]]  # E,P,T,D
    p1 = traj[ei, pi, i0[:, None, :] + 1]  # E,P,T,D
    return (1.0 - w) * p0 + w * p1  # E,P,T,D


def simulate(
    n_episodes: int, seed: int = 0, config: RoboSimConfig | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Simulate Robo episodes.

    Args:
        n_episodes: number of episodes E (>= 0).
        seed: seed of ``numpy.random.default_rng``; the output is a deterministic
            function of ``(n_episodes, seed, config)``.
        config: simulator parameters (defaults tuned on the official val set).

    Returns:
        ``(history [E,3,8,2], future [E,3,12,2])`` float32 arrays in metres, agent
        0 = leader, 1 = follower (the pair walking together), 2 = approacher.
    """
    if (
        isinstance(n_episodes, bool)
        or not isinstance(n_episodes, (int, np.integer))
        or n_episodes < 0
    ):
        raise ConfigError(f"n_episodes must be an int >= 0, got {n_episodes!r}")
    cfg = RoboSimConfig() if config is None else config
    if not isinstance(cfg, RoboSimConfig):
        raise TypeError(f"config must be a RoboSimConfig, got {type(cfg).__name__}")
    rng = np.random.default_rng(seed)
    out = np.empty((int(n_episodes), N_AGENTS, N_FRAMES, 2), dtype=np.float32)  # E,P,T,D
    for lo in range(0, int(n_episodes), _CHUNK):
        hi = min(lo + _CHUNK, int(n_episodes))
        out[lo:hi] = _simulate_chunk(hi - lo, rng, cfg)
    return out[:, :, :N_HISTORY].copy(), out[:, :, N_HISTORY:].copy()


# ----------------------------------------------------------------------------- statistics


def _pct(x: np.ndarray, q: float) -> float:
    return float(np.percentile(x, q)) if x.size else float("nan")


def scene_statistics(
    history: np.ndarray, future: np.ndarray, arena_size: float | None = None
) -> dict[str, float]:
    """Summary statistics of Robo scenes (used to tune and check robo-sim).

    Args:
        history: [E,P,8,2] positions in metres (agent 0 leader, 1 follower, 2 approacher).
        future: [E,P,12,2] positions in metres.
        arena_size: arena side for the "on wall" fraction (default: RoboSimConfig().arena_size).

    Returns:
        A flat dict of floats. Speeds in m/s, distances in m, angles in degrees.
    """
    size = RoboSimConfig().arena_size if arena_size is None else arena_size
    xy = np.concatenate([history, future], axis=2).astype(np.float64)  # E,P,T,D
    n_agents = xy.shape[1]
    step = np.diff(xy, axis=2)  # E,P,T-1,D
    speed = np.hypot(step[..., 0], step[..., 1]) / FRAME_DT  # E,P,T-1
    s: dict[str, float] = {"episodes": float(xy.shape[0])}

    s["speed_mean"] = float(speed.mean())
    s["speed_std"] = float(speed.std())
    for q in (5, 25, 50, 75, 95):
        s[f"speed_p{q:02d}"] = _pct(speed, q)
    for a in range(n_agents):
        s[f"speed_mean_a{a}"] = float(speed[:, a].mean())
        s[f"speed_std_a{a}"] = float(speed[:, a].std())
    s["stationary_frac"] = float((speed < 0.05).mean())
    # frame-to-frame speed change (captures sampling noise)
    s["speed_change_abs_mean"] = float(np.abs(np.diff(speed, axis=2)).mean())

    pts = xy.reshape(-1, 2)
    for k, name in enumerate("xy"):
        s[f"{name}_min"] = float(pts[:, k].min())
        s[f"{name}_max"] = float(pts[:, k].max())
        s[f"{name}_p01"] = _pct(pts[:, k], 1)
        s[f"{name}_p99"] = _pct(pts[:, k], 99)
    on_wall = (np.abs(xy) < 0.01) | (np.abs(xy - size) < 0.01)  # E,P,T,D
    s["on_wall_frac"] = float(on_wall.any(-1).mean())

    # pairwise distances over the 20 frames
    diff = xy[:, :, None] - xy[:, None, :]  # E,P,P,T,D
    dist = np.hypot(diff[..., 0], diff[..., 1])  # E,P,P,T
    iu = np.triu_indices(n_agents, 1)
    closest = dist[:, iu[0], iu[1]].min(axis=(1, 2))  # E
    s["closest_mean"] = float(closest.mean())
    for q in (5, 25, 50, 75, 95):
        s[f"closest_p{q:02d}"] = _pct(closest, q)
    if n_agents >= 3:
        pair = dist[:, 0, 1]  # E,T
        s["pair_dist_mean"] = float(pair.mean())
        for q in (5, 50, 95):
            s[f"pair_dist_p{q:02d}"] = _pct(pair, q)
        app = np.minimum(dist[:, 2, 0], dist[:, 2, 1]).min(axis=1)  # E
        s["approach_min_mean"] = float(app.mean())
        for q in (10, 50):
            s[f"approach_min_p{q:02d}"] = _pct(app, q)
        s["approach_min_lt1m_frac"] = float((app < 1.0).mean())
        mid0 = 0.5 * (xy[:, 0, 0] + xy[:, 1, 0])  # E,D
        s["approach_start_dist_mean"] = float(np.hypot(*(xy[:, 2, 0] - mid0).T).mean())

    # heading changes between consecutive displacements (both moving >= 0.1 m/s)
    heading = np.arctan2(step[..., 1], step[..., 0])  # E,P,T-1
    moving = speed >= 0.1  # E,P,T-1
    turn = np.abs(_wrap(np.diff(heading, axis=2)))  # E,P,T-2
    valid = moving[..., 1:] & moving[..., :-1]  # E,P,T-2
    turn_deg = np.degrees(turn[valid])
    s["turn_step_mean_deg"] = float(turn_deg.mean()) if turn_deg.size else float("nan")
    s["turn_step_p50_deg"] = _pct(turn_deg, 50)
    s["turn_step_p90_deg"] = _pct(turn_deg, 90)
    s["turn_step_gt30_frac"] = float((turn_deg > 30).mean()) if turn_deg.size else float("nan")
    total = np.degrees(np.where(valid, turn, 0.0).sum(axis=2))  # E,P
    s["turn_total_mean_deg"] = float(total.mean())
    s["turn_total_p50_deg"] = _pct(total, 50)
    s["turn_total_p90_deg"] = _pct(total, 90)
    for a in range(n_agents):
        s[f"turn_total_mean_a{a}_deg"] = float(total[:, a].mean())
    return s
