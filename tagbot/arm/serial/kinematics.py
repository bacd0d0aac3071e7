"""Serial arms from an MJCF description: forward kinematics by MuJoCo, paths by mink's IK.

SI units throughout, as MuJoCo: metres, radians, seconds. The model names the pen's point with
a site ``pen_tip`` whose +x axis is the pen axis (from the holder towards the point), and may
name an ``end_effector`` site from which ``tool_offset`` places the point. Joint velocity limits
(rad/s) come from the model's custom numeric ``joint_velocity_limit``, one per joint.

:meth:`SerialArm.solve_path` solves a path point by point with mink's differential IK (a QP per
iteration, solver daqp): a position task on the pen tip, a light axis-alignment task pulling the
pen towards the paper's normal, and as inequalities the joint limits, the velocity limits (a
step bound per iteration) and the tilt cone (:class:`TiltLimit`). Each point is iterated until
the tip is within ``tol`` of it (1 µm by default), warm-started from the previous solution
extrapolated linearly; points more than 2 mm apart are joined through points 2 mm apart, so the
joints move continuously along the path. A point that cannot be reached, needs a joint beyond
its range, tilts the pen too far, makes the arm touch itself or moves a joint more than
``max_step`` in 2 mm raises :class:`~tagbot.errors.ReachError` naming its index and the reason.
Cost: about 0.15-0.25 ms per point on a table, 0.3-0.4 ms on a board whose normal leaves the
arm's plane (one core, tags sampled at 100 Hz).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import mink
import mujoco
import numpy as np
from numpy.typing import ArrayLike, NDArray

from tagbot.arm.serial import OPEN_MANIPULATOR_X
from tagbot.errors import PlacementError, ProfileError, ReachError

__all__ = ["PEN_SITE", "SerialArm", "TiltLimit"]

Array = NDArray[np.float64]
PEN_SITE = "pen_tip"
"""The site at the pen's point; its +x axis is the pen axis."""
EE_SITE = "end_effector"
VELOCITY_NUMERIC = "joint_velocity_limit"
SOLVER = "daqp"


def _site_axis(data: mujoco.MjData, site: int) -> Array:
    """The site's +x axis in the world."""
    return data.site_xmat[site].reshape(3, 3)[:, 0].copy()


def _tilt(axis: Array, normal: Array) -> float:
    """Angle (rad) between the pen axis and the direction into the paper (``−normal``)."""
    return math.acos(max(-1.0, min(1.0, -float(axis @ normal))))


class TiltLimit(mink.Limit):
    """The pen axis within ``max_tilt`` of ``−normal`` (pointing into the paper), as a QP row.

    With ``a`` the pen axis and ``c = −a·n``, a joint step ``Δq`` turns ``a`` by ``ω = J_r Δq``
    and changes ``c`` by ``−ω·(a × n)`` to first order, so ``c ≥ cos(max_tilt)`` becomes
    ``(a × n)ᵀ J_r Δq ≤ gain·(c − cos(max_tilt))``. Outside the cone the row only forbids
    tilting further (``h = 0``), and the alignment task brings the pen back.
    """

    def __init__(
        self, model: mujoco.MjModel, site: int, normal: Array, max_tilt: float, gain: float = 0.95
    ) -> None:
        self.site = site
        self.normal = normal
        self.cos_max = math.cos(max_tilt)
        self.gain = gain
        self._jr = np.zeros((3, model.nv))

    def compute_qp_inequalities(
        self, configuration: mink.Configuration, dt: float
    ) -> mink.Constraint:
        del dt  # a position bound, not a rate
        a = _site_axis(configuration.data, self.site)
        mujoco.mj_jacSite(configuration.model, configuration.data, None, self._jr, self.site)
        g = np.cross(a, self.normal) @ self._jr
        h = max(0.0, self.gain * (-float(a @ self.normal) - self.cos_max))
        return mink.Constraint(G=g[None, :], h=np.array([h]))


@dataclass
class SerialArm:
    """A serial arm's MuJoCo model with its pen: joints, limits and the pen tip's site."""

    model: mujoco.MjModel
    path: Path
    joint_names: tuple[str, ...]
    lower: Array
    upper: Array
    velocity: Array
    arm_geoms: NDArray[np.bool_]
    """Geoms on the arm's bodies (the first joint's body's parent and below), not a scene's."""

    @classmethod
    def load(
        cls,
        model_path: str | Path = OPEN_MANIPULATOR_X,
        tool_offset: float | ArrayLike | None = None,
    ) -> SerialArm:
        """Load an MJCF (or URDF) description; ``tool_offset`` (m) puts the pen's point there in
        the ``end_effector`` site's frame (a number: that far along its x axis). Raises
        :class:`~tagbot.errors.ProfileError` naming the file and the problem."""
        path = Path(model_path)
        try:
            spec = mujoco.MjSpec.from_file(str(path))
        except (
            ValueError,
            OSError,
        ) as exc:  # mujoco reports a missing file or bad XML as ValueError
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise ProfileError(f"{path}: cannot load the robot description: {first}") from None
        if tool_offset is not None:
            cls._place_tool(spec, path, tool_offset)
        try:
            model = spec.compile()
        except ValueError as exc:
            raise ProfileError(f"{path}: cannot compile the robot description: {exc}") from None
        if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, PEN_SITE) < 0:
            raise ProfileError(f"{path}: no site {PEN_SITE!r} (the pen's point)")
        if model.njnt != model.nq or model.nq != model.nv or model.nq == 0:
            raise ProfileError(
                f"{path}: the arm must have hinge or slide joints only, got nq={model.nq}"
            )
        if not np.all(model.jnt_limited):
            raise ProfileError(f"{path}: every joint needs a range")
        names = tuple(model.joint(j).name for j in range(model.njnt))
        try:
            velocity = np.array(model.numeric(VELOCITY_NUMERIC).data, dtype=float)
        except KeyError:
            raise ProfileError(f"{path}: no custom numeric {VELOCITY_NUMERIC!r}") from None
        if velocity.shape != (model.nq,) or not np.all(velocity > 0):
            raise ProfileError(
                f"{path}: {VELOCITY_NUMERIC}: need {model.nq} positive values, "
                f"got {velocity.tolist()}"
            )
        rng = model.jnt_range.copy()
        root = int(model.body_parentid[model.jnt_bodyid[0]])
        mine = np.zeros(model.ngeom, dtype=bool)
        mine[mink.get_subtree_geom_ids(model, root) if root > 0 else slice(None)] = True
        return cls(model, path, names, rng[:, 0].copy(), rng[:, 1].copy(), velocity, mine)

    @staticmethod
    def _place_tool(spec: mujoco.MjSpec, path: Path, tool_offset: float | ArrayLike) -> None:
        """Move the ``pen_tip`` site (and a capsule ``pen_nib`` ending at it) by the offset."""
        off = np.atleast_1d(np.asarray(tool_offset, dtype=float))
        if off.shape == (1,):
            off = np.array([off[0], 0.0, 0.0])
        if off.shape != (3,) or not np.all(np.isfinite(off)):
            raise ProfileError(
                f"{path}: tool_offset: need a number or 3 numbers (m), got {tool_offset!r}"
            )
        ee, tip = spec.site(EE_SITE), spec.site(PEN_SITE)
        if ee is None or tip is None:
            raise ProfileError(f"{path}: tool_offset needs sites {EE_SITE!r} and {PEN_SITE!r}")
        tip.pos = np.asarray(ee.pos) + off
        nib = spec.geom("pen_nib")
        if nib is not None and nib.type == mujoco.mjtGeom.mjGEOM_CAPSULE:
            start = np.asarray(nib.fromto[:3], dtype=float)
            d = tip.pos - start
            length = float(np.linalg.norm(d))
            if length <= nib.size[0]:
                raise ProfileError(f"{path}: tool_offset: the pen's point is inside the holder")
            end = start + d * (1.0 - nib.size[0] / length)  # the capsule's cap ends at the point
            nib.fromto = np.concatenate([start, end])

    @property
    def n_joints(self) -> int:
        return self.model.nq

    def fk(self, q: ArrayLike) -> tuple[Array, Array]:
        """Pen-tip positions and pen axes (unit) of joint angles ``(N, nq)`` (or one ``(nq,)``)."""
        qs = np.asarray(q, dtype=float)
        flat = qs.reshape(-1, self.n_joints)
        data = mujoco.MjData(self.model)
        site = self.model.site(PEN_SITE).id
        pos = np.empty((len(flat), 3))
        axis = np.empty((len(flat), 3))
        for i, qi in enumerate(flat):
            data.qpos[:] = qi
            mujoco.mj_kinematics(self.model, data)
            pos[i] = data.site_xpos[site]
            axis[i] = _site_axis(data, site)
        shape = (*qs.shape[:-1], 3)
        return pos.reshape(shape), axis.reshape(shape)

    def contacts(self, q: ArrayLike) -> list[tuple[str, str]]:
        """The pairs of the arm's own geoms in contact at ``q`` (adjacent links are excluded)."""
        data = mujoco.MjData(self.model)
        data.qpos[:] = np.asarray(q, dtype=float)
        mujoco.mj_kinematics(self.model, data)
        return self._self_contacts(data)

    def _self_contacts(self, data: mujoco.MjData) -> list[tuple[str, str]]:
        mujoco.mj_collision(self.model, data)
        if data.ncon == 0:
            return []
        pairs = data.contact.geom[: data.ncon]
        mine = self.arm_geoms[pairs].all(axis=1)
        return [(self.model.geom(a).name, self.model.geom(b).name) for a, b in pairs[mine]]

    def solve_path(
        self,
        points: ArrayLike,
        normal: ArrayLike,
        max_tilt: float,
        q0: ArrayLike,
        *,
        tol: float = 1e-6,
        max_step: float = 0.25,
        max_iter: int = 200,
    ) -> Array:
        """Joint angles ``(N, nq)`` putting the pen tip on each point ``(N, 3)`` (m) within
        ``tol`` (m), the pen axis within ``max_tilt`` (rad) of ``−normal`` (the paper's normal
        points out of the paper, towards the arm), starting from ``q0``.

        Raises :class:`~tagbot.errors.ReachError` at the first point that cannot be reached
        (``reach``), needs a joint beyond its range (``joint limit``), tilts the pen too far
        (``tilt``), makes the arm touch itself (``self-collision``), or moves a joint by more
        than ``max_step`` (rad) per 2 mm of the tip's travel (``jump``: a branch flip or a
        singularity; points further apart are followed through points 2 mm apart).
        """
        pts = np.asarray(points, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) == 0 or not np.all(np.isfinite(pts)):
            raise PlacementError(f"points: need finite (N, 3) positions, got shape {pts.shape}")
        n = np.asarray(normal, dtype=float)
        if n.shape != (3,) or not np.all(np.isfinite(n)) or np.linalg.norm(n) == 0:
            raise PlacementError(f"normal: need a non-zero 3-vector, got {normal!r}")
        n = n / np.linalg.norm(n)
        if not 0.0 <= max_tilt < math.pi / 2:
            raise PlacementError(f"max_tilt: must be in [0, π/2) rad, got {max_tilt!r}")
        start = np.asarray(q0, dtype=float)
        if start.shape != (self.n_joints,):
            raise PlacementError(f"q0: need {self.n_joints} joint angles, got shape {start.shape}")
        if np.any(start < self.lower) or np.any(start > self.upper):
            j = int(np.argmax((start < self.lower) | (start > self.upper)))
            raise PlacementError(
                f"q0: {self.joint_names[j]} = {start[j]:.4f} rad is outside its range "
                f"{self.lower[j]:.4f}…{self.upper[j]:.4f}"
            )
        return _PathSolver(self, n, max_tilt, tol, max_iter).run(pts, start, max_step)


class _PathSolver:
    """One path's IK state: mink's configuration, tasks and limits."""

    DT = 0.01  # the QP's step: joint steps ≤ velocity × DT per iteration (a trust region)
    ALIGN_COST = 0.05  # the axis task's weight against the tip's position (1/m)
    DAMPING = 1e-6
    SETTLE = 1e-5  # rad: an iteration moving no joint more than this has settled the pen's axis
    GAP = 0.002  # m: longer gaps between points are followed in steps this long
    SHARED = 1  # iterations with both tasks before the position alone, after the first point
    STALL = 1e-9  # rad: an iteration moving no joint more than this has stopped

    def __init__(self, arm: SerialArm, normal: Array, max_tilt: float, tol: float, max_iter: int):
        m = arm.model
        self.arm = arm
        self.normal = normal
        self.max_tilt = max_tilt
        self.tol = tol
        self.max_iter = max_iter
        self.site = m.site(PEN_SITE).id
        self.cfg = mink.Configuration(m)
        self.position = mink.FrameTask(PEN_SITE, "site", position_cost=1.0, orientation_cost=0.0)
        self.align = mink.AxisAlignTask(
            PEN_SITE, "site", axis=(1.0, 0.0, 0.0), cost=self.ALIGN_COST
        )
        self.align.set_target(-normal)
        velocity = dict(zip(arm.joint_names, arm.velocity, strict=True))
        self.bounds: list[mink.Limit] = [
            mink.ConfigurationLimit(m),
            mink.VelocityLimit(m, velocity),
        ]
        self.tilt = TiltLimit(m, self.site, normal, max_tilt)

    def tip(self) -> Array:
        return self.cfg.data.site_xpos[self.site]

    def converge(
        self,
        target: Array,
        tasks: list[mink.Task],
        limits: list[mink.Limit],
        settle: bool,
        budget: int | None = None,
    ) -> bool:
        """Iterate the QP until the tip is within ``tol`` of ``target`` (and, with ``settle``,
        the steps have become negligible); False when the steps stall short of it or
        ``budget`` (default ``max_iter``) iterations do not get there."""
        self.position.set_target(mink.SE3.from_translation(target))
        for _ in range(self.max_iter if budget is None else budget):
            near = bool(np.linalg.norm(self.tip() - target) < self.tol)
            if near and not settle:
                return True
            try:
                v = mink.solve_ik(self.cfg, tasks, self.DT, SOLVER, self.DAMPING, limits=limits)
            except mink.NoSolutionFound:
                return False
            self.cfg.integrate_inplace(v, self.DT)
            step = float(np.max(np.abs(v))) * self.DT
            if step < self.SETTLE:
                settle = False
                if step < self.STALL:
                    break
        return bool(np.linalg.norm(self.tip() - target) < self.tol)

    def solve_point(self, target: Array, guess: Array, first: bool) -> bool:
        """The tip on ``target`` from ``guess``: both tasks, then the position alone (the axis
        task's pull can leave the tip a little off when the paper's normal is out of reach).
        The first point comes from anywhere: its tilt is checked after, not held on the way."""
        self.cfg.update(guess)
        limits = list(self.bounds) if first else [*self.bounds, self.tilt]
        budget = None if first else self.SHARED
        if self.converge(target, [self.position, self.align], limits, first, budget):
            return True
        return self.converge(target, [self.position], limits, False)

    def run(self, pts: Array, q0: Array, max_step: float) -> Array:
        """Each point in turn; a gap longer than ``GAP`` is followed through points ``GAP``
        apart on the segment, each checked like the points themselves."""
        out = np.empty((len(pts), self.arm.n_joints))
        self.place(0, pts[0], q0, first=True)
        q1, p1 = self.cfg.q.copy(), pts[0]
        q2: Array | None = None
        p2 = p1
        out[0] = q1
        for i in range(1, len(pts)):
            gap = float(np.linalg.norm(pts[i] - p1))
            count = max(1, math.ceil(gap / self.GAP - 1e-9))
            start = p1
            for k in range(1, count + 1):
                target = pts[i] if k == count else start + (pts[i] - start) * (k / count)
                guess = q1
                if q2 is not None:  # linear extrapolation: the next joints to second order
                    before = float(np.linalg.norm(p1 - p2))
                    ratio = min(1.0, float(np.linalg.norm(target - p1)) / before) if before else 0.0
                    guess = np.clip(q1 + ratio * (q1 - q2), self.arm.lower, self.arm.upper)
                try:
                    q = self.step(i, target, guess, q1, p1, max_step)
                except ReachError as exc:
                    if k == count:
                        raise
                    way = f"{exc.detail}, on the way from point {i - 1}"
                    raise ReachError(way, i, exc.reason) from None
                q2, p2, q1, p1 = q1, p1, q, target
            out[i] = q1
        return out

    def step(
        self, i: int, target: Array, guess: Array, q1: Array, p1: Array, max_step: float
    ) -> Array:
        """The pen on ``target`` after ``p1`` (reached at ``q1``): no joint moves more than
        ``max_step``."""
        self.place(i, target, guess, first=False)
        q = self.cfg.q.copy()
        jump = np.abs(q - q1)
        j = int(np.argmax(jump))
        if jump[j] > max_step:
            raise ReachError(
                f"{self.arm.joint_names[j]} would jump by {jump[j]:.3f} rad in "
                f"{np.linalg.norm(target - p1) * 1e3:.2f} mm (max {max_step} rad per "
                f"{self.GAP * 1e3:g} mm): a branch flip or a singularity",
                i,
                "jump",
            )
        return q

    def place(self, i: int, target: Array, guess: Array, first: bool) -> None:
        """The pen on ``target`` (for point ``i``), then the tilt and self-contacts checked."""
        if not self.solve_point(target, guess, first):
            self.fall_back(i, target, guess)
        tilt = _tilt(_site_axis(self.cfg.data, self.site), self.normal)
        if tilt > self.max_tilt + 1e-9:
            raise ReachError(
                f"the pen axis would be {math.degrees(tilt):.1f}° from the paper's normal "
                f"(max {math.degrees(self.max_tilt):.1f}°)",
                i,
                "tilt",
            )
        touching = self.arm._self_contacts(self.cfg.data)
        if touching:
            a, b = touching[0]
            raise ReachError(f"the arm would touch itself ({a} against {b})", i, "self-collision")

    def fall_back(self, i: int, target: Array, guess: Array) -> None:
        """Point ``i`` by the position alone within the ranges, if that is within the tilt;
        otherwise name why it is out: the tilt, a joint limit (reachable only outside the
        ranges), or the reach."""
        closest = np.linalg.norm(self.tip() - target) * 1e3
        where = f"({target[0]:.4f}, {target[1]:.4f}, {target[2]:.4f}) m"
        self.cfg.update(guess)
        if self.converge(target, [self.position], list(self.bounds), True):
            tilt = _tilt(_site_axis(self.cfg.data, self.site), self.normal)
            if tilt <= self.max_tilt:
                return
            raise ReachError(
                f"the pen at {where} would tilt {math.degrees(tilt):.1f}° from the paper's "
                f"normal (max {math.degrees(self.max_tilt):.1f}°)",
                i,
                "tilt",
            )
        self.cfg.update(guess)
        if self.converge(target, [self.position], [self.bounds[1]], True):
            q = self.cfg.q
            out = np.maximum(self.arm.lower - q, q - self.arm.upper)
            j = int(np.argmax(out))
            if out[j] > 0:
                raise ReachError(
                    f"the pen at {where} needs {self.arm.joint_names[j]} = {q[j]:.3f} rad, "
                    f"outside its range {self.arm.lower[j]:.3f}…{self.arm.upper[j]:.3f}",
                    i,
                    "joint limit",
                )
        raise ReachError(
            f"{where} is out of the arm's reach (the pen's point gets no closer than "
            f"{closest:.2f} mm)",
            i,
            "reach",
        )
