"""MuJoCo contact physics for the twin's grasp, lift and set-down (the ``mujoco`` physics mode).

What is simulated: the table top (a plane at z = 0 of ``base``), the object as a free rigid body (its
convex parts from ``collision_shapes``, mass from their volume and a density), and the RH-P12-RN's two
finger pads as boxes (``GripperSpec`` sizes) on a position-controlled hand: the hand is a MuJoCo *mocap*
body that follows the arm's TCP pose exactly (the arm is position-controlled and far stronger than the
object), the pads slide across it on two joints driven by force-limited position actuators (the gripper's
current-limited grip), and each pad's pull-back along the approach as it opens (the parallel linkage,
``GripperSpec.retraction``) is a polynomial joint coupling.

Nothing is drawn: whether a grasp holds, how the object turns in the hand while the pads close (a box
closed on at an angle swings until its faces lie on the pads), how far it pivots when lifted off-centre,
whether it slides out, and how it lands, bounces, tilts or topples when the pads open at the set-down
all come from the contact dynamics. The seed only perturbs the physical parameters a real cell does not
know exactly (friction and mass within ``*_jitter``); MuJoCo itself is deterministic, so one seed gives
one outcome.

A closed hand that moves through the object pushes it (``push``): the twin runs it for every set-point
of such a sweep, continuing one simulation while consecutive set-points follow on, so the object slides,
turns or tips as the pads drive it.

Not simulated: the arm's links and the palm (the grasp planner keeps them clear), the carry between
the lift and the set-down (the in-hand pose found after the lift is kept while the wrist turns), and
the approach of an open hand (the geometric checker still rejects pads that would hit the table or the
object on the way in, ``gripper.GraspChecker``).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, fields

import mujoco
import numpy as np

from common.geometry import invert, make_transform
from services.sim.catalogue import SimObject
from services.sim.collision_shapes import convex_parts
from services.sim.errors import SimInputError
from services.sim.gripper import GripperSpec

PHYSICS_MODES = ("mujoco", "geometric")


@dataclass(frozen=True)
class PhysicsConfig:
    """Physical parameters of the mujoco mode. Defaults: cardboard/tin household objects on a wooden
    table, rubber-tipped pads, the RH-P12-RN closed at a moderate current."""

    timestep: float = 0.002  # s
    density: float = 400.0  # kg/m^3 over the object's closed volume (a filled box of cereal/cheese ~300-600)
    pad_friction: float = 1.0  # rubber pad on cardboard
    object_friction: float = 0.45  # cardboard on wood (MuJoCo takes the larger of a pair's coefficients)
    torsional_friction: float = 0.004  # m: resistance to spinning about a contact normal (a patch, not a point)
    grip_force: float = 25.0  # N per pad when closed on an object (current limit)
    close_time: float = 0.35  # s to drive the pads from their opening to the commanded width
    lift_height: float = 0.04  # m lifted to test the hold
    lift_time: float = 0.4  # s
    hold_time: float = 0.4  # s held still after the lift
    open_time: float = 0.25  # s for the pads to open at the set-down
    retreat: float = 0.05  # m the hand backs off along its approach after opening
    settle_time: float = 1.5  # s at most for the object to come to rest
    friction_jitter: float = 0.1  # relative uniform spread of every friction coefficient, drawn per seed
    mass_jitter: float = 0.1  # relative uniform spread of the object's mass, drawn per seed
    collision: str = "auto"  # "auto" (hull if nearly convex, else coacd), "coacd" (decomposition, cached), "hull"
    topple_tilt_deg: float = 30.0  # an object resting tilted more than this has toppled
    mass: float = 0.0  # kg: the object's mass (its inertia scaled to match); 0 = density x its closed volume
    push_speed: float = 0.03  # m/s a closed hand sweeping through the object moves at (the arm's approach speed)

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "collision":
                if v not in ("auto", "coacd", "hull"):
                    raise SimInputError(f"collision must be 'auto', 'coacd' or 'hull', got {v!r}", code="bad_value")
                continue
            if not np.isfinite(v) or v < 0:
                raise SimInputError(f"physics {f.name} must be a finite non-negative number, got {v!r}",
                                    code="bad_value", detail={f.name: v})
        if self.timestep <= 0 or self.timestep > 0.01:
            raise SimInputError("physics timestep must be in (0, 0.01] s", code="bad_value")
        if self.friction_jitter >= 1 or self.mass_jitter >= 1:
            raise SimInputError("friction_jitter and mass_jitter must be below 1", code="bad_value")


@dataclass(frozen=True)
class PhysicsGrasp:
    """What closing the pads and lifting did. ``reason``: "ok", "slip" (held when closed, lost while
    lifting) or "no_grip" (the pads closed without holding the object)."""

    held: bool
    reason: str
    width: float  # opening between the pads at the end (m)
    T_gripper_object: np.ndarray | None  # in-hand pose after the lift (held only)
    T_base_object: np.ndarray  # where the object is at the end (in the hand, or back on the table)
    in_hand_turn_deg: float  # how far the object turned relative to the hand from the approach to the end
    pad_state: tuple[float, ...] | None  # the pads' joint positions holding it (held only), for the set-down
    message: str


@dataclass(frozen=True)
class PhysicsSetDown:
    """Where the released object came to rest and how it got there."""

    T_base_object: np.ndarray
    tilt_deg: float  # angle between the object's up axis and the table normal at rest
    toppled: bool
    bounce_m: float  # highest rise of the object's centre above where it was released
    settled: bool  # came to rest within ``settle_time``
    message: str


def _quat(R: np.ndarray) -> np.ndarray:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(R, dtype=np.float64).reshape(9))
    return q


def _pose(pos: np.ndarray, quat: np.ndarray) -> np.ndarray:
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, quat)
    return make_transform(R.reshape(3, 3), pos)


def _smooth(s: float) -> float:
    s = min(max(s, 0.0), 1.0)
    return s * s * (3 - 2 * s)


def tilt_deg(T: np.ndarray) -> float:
    """Angle (deg) between a pose's z axis and base z."""
    return float(np.degrees(np.arccos(np.clip(T[2, 2], -1.0, 1.0))))


class PhysicsScene:
    """One object, the table and the two pads in MuJoCo, built once per object; every call starts from a
    fresh state, so calls are independent of each other and of their order."""

    def __init__(self, obj: SimObject, spec: GripperSpec | None = None, config: PhysicsConfig | None = None):
        self.spec = spec or GripperSpec()
        self.config = config or PhysicsConfig()
        self.parts, self.collision_method = convex_parts(obj.vertices, obj.triangles, self.config.collision)
        self.model = mujoco.MjModel.from_xml_string(self._xml())
        if self.config.mass > 0:  # a given mass: the density's inertia scaled to it (same shape, same centre)
            body = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, "object")
            scale = self.config.mass / float(self.model.body_mass[body])
            self.model.body_mass[body] *= scale
            self.model.body_inertia[body] *= scale
        self._base_friction = self.model.geom_friction.copy()
        self._base_mass = self.model.body_mass.copy()
        self._base_inertia = self.model.body_inertia.copy()
        m = self.model
        self._obj = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "object")
        self._hand = m.body_mocapid[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "target")]
        self._hand_qpos = m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "hand_free")]
        self._obj_qpos = m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "object_free")]
        self._obj_dof = m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "object_free")]
        self._pad_q = [m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n)]
                       for n in ("left_y", "left_x", "right_y", "right_x")]
        self._pad_geoms = {mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, n) for n in ("left_pad", "right_pad")}
        self._obj_geoms = {g for g in range(m.ngeom) if m.geom_bodyid[g] == self._obj}
        self._lock = threading.Lock()
        # the push under way: its simulation, where it left the hand and the object (``push``)
        self._sweep: tuple[mujoco.MjData, np.ndarray, np.ndarray] | None = None
        pts = np.vstack(self.parts)
        self._centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
        self._radius = float(np.linalg.norm(pts - self._centre, axis=1).max())

    @property
    def mass(self) -> float:
        """The object's nominal mass (kg)."""
        return float(self._base_mass[self._obj])

    # -- model --------------------------------------------------------------------------------------------
    def _xml(self) -> str:
        s, c = self.spec, self.config
        # x pull-back of a pad against its half opening q: x = -retraction(2 q), a quartic fit
        o = np.asarray(s.retraction_openings)
        coef = np.polyfit(o / 2.0, -np.asarray(s.retraction), 4)[::-1]  # a0 + a1 q + ... + a4 q^4
        poly = " ".join(f"{a:.8g}" for a in coef)
        hx, hy, hz = s.pad_length / 2, s.pad_thickness / 2, s.pad_height / 2
        meshes = "\n".join(
            f'<mesh name="part{i}" vertex="{" ".join(f"{x:.6f}" for x in p.reshape(-1))}" maxhullvert="64"/>'
            for i, p in enumerate(self.parts))
        geoms = "\n".join(f'<geom type="mesh" mesh="part{i}" class="object"/>' for i in range(len(self.parts)))
        stroke = s.max_opening / 2
        force = f"-{c.grip_force} {c.grip_force}"
        pad_fr = f"{c.pad_friction} {c.torsional_friction} 0.0001"
        return f"""
<mujoco model="objscan_grasp">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{c.timestep}" cone="elliptic" impratio="10" integrator="implicitfast"/>
  <default>
    <default class="object">
      <geom density="{c.density}" friction="{c.object_friction} {c.torsional_friction} 0.0001" condim="4"
            solref="0.004 1" solimp="0.95 0.99 0.001"/>
    </default>
    <default class="pad">
      <geom type="box" size="{hx} {hy} {hz}" density="1200" friction="{pad_fr}" condim="4"
            solref="0.004 1" solimp="0.95 0.99 0.001"/>
    </default>
  </default>
  <asset>{meshes}</asset>
  <worldbody>
    <geom name="table" type="plane" size="2 2 0.01" friction="{c.object_friction} {c.torsional_friction} 0.0001"/>
    <body name="target" mocap="true"/>
    <body name="hand" gravcomp="1">
      <freejoint name="hand_free"/>
      <inertial pos="0 0 0" mass="1.0" diaginertia="0.002 0.002 0.002"/>
      <body name="left" gravcomp="1">
        <joint name="left_y" type="slide" axis="0 1 0" range="0 {stroke}" damping="30"/>
        <joint name="left_x" type="slide" axis="1 0 0" range="-0.05 0.01"/>
        <geom name="left_pad" class="pad" pos="0 {hy} 0"/>
      </body>
      <body name="right" gravcomp="1">
        <joint name="right_y" type="slide" axis="0 -1 0" range="0 {stroke}" damping="30"/>
        <joint name="right_x" type="slide" axis="1 0 0" range="-0.05 0.01"/>
        <geom name="right_pad" class="pad" pos="0 -{hy} 0"/>
      </body>
    </body>
    <body name="object">
      <freejoint name="object_free"/>
      {geoms}
    </body>
  </worldbody>
  <contact><exclude body1="left" body2="right"/></contact>
  <equality>
    <weld body1="target" body2="hand" solref="0.002 1"/>
    <joint joint1="left_x" joint2="left_y" polycoef="{poly}" solref="0.004 1"/>
    <joint joint1="right_x" joint2="right_y" polycoef="{poly}" solref="0.004 1"/>
  </equality>
  <actuator>
    <position name="left" joint="left_y" kp="4000" forcerange="{force}" ctrlrange="0 {stroke}"/>
    <position name="right" joint="right_y" kp="4000" forcerange="{force}" ctrlrange="0 {stroke}"/>
  </actuator>
</mujoco>"""

    # -- state helpers ------------------------------------------------------------------------------------
    def _start(self, rng: np.random.Generator | None) -> mujoco.MjData:
        """A fresh state with this seed's friction and mass."""
        m, c = self.model, self.config
        m.geom_friction[:] = self._base_friction
        m.body_mass[:] = self._base_mass
        m.body_inertia[:] = self._base_inertia
        if rng is not None:
            f = 1.0 + rng.uniform(-c.friction_jitter, c.friction_jitter, m.ngeom)
            m.geom_friction[:, 0] = self._base_friction[:, 0] * f
            k = 1.0 + rng.uniform(-c.mass_jitter, c.mass_jitter)
            m.body_mass[self._obj] = self._base_mass[self._obj] * k
            m.body_inertia[self._obj] = self._base_inertia[self._obj] * k
        d = mujoco.MjData(m)
        mujoco.mj_resetData(m, d)
        return d

    def _set_hand(self, d: mujoco.MjData, T: np.ndarray, *, teleport: bool = False) -> None:
        """Move the hand's target (the TCP pose); ``teleport`` also puts the hand there at rest."""
        d.mocap_pos[self._hand] = T[:3, 3]
        d.mocap_quat[self._hand] = _quat(T[:3, :3])
        if teleport:
            a = self._hand_qpos
            d.qpos[a:a + 3] = T[:3, 3]
            d.qpos[a + 3:a + 7] = _quat(T[:3, :3])

    def _set_pads(self, d: mujoco.MjData, opening: float) -> None:
        half = float(np.clip(opening / 2, 0.0, self.spec.max_opening / 2))
        x = self.spec.pad_center_x(2 * half)
        ly, lx, ry, rx = self._pad_q
        d.qpos[ly], d.qpos[lx], d.qpos[ry], d.qpos[rx] = half, x, half, x
        d.ctrl[:] = half

    def _set_object(self, d: mujoco.MjData, T: np.ndarray) -> None:
        a = self._obj_qpos
        d.qpos[a:a + 3] = T[:3, 3]
        d.qpos[a + 3:a + 7] = _quat(T[:3, :3])
        d.qvel[self._obj_dof:self._obj_dof + 6] = 0.0

    def _object_pose(self, d: mujoco.MjData) -> np.ndarray:
        a = self._obj_qpos
        return _pose(d.qpos[a:a + 3].copy(), d.qpos[a + 3:a + 7].copy())

    def _width(self, d: mujoco.MjData) -> float:
        return float(d.qpos[self._pad_q[0]] + d.qpos[self._pad_q[2]])

    def _pads_touching(self, d: mujoco.MjData) -> set[int]:
        touching = set()
        for i in range(d.ncon):
            g1, g2 = int(d.contact[i].geom1), int(d.contact[i].geom2)
            for a, b in ((g1, g2), (g2, g1)):
                if a in self._pad_geoms and b in self._obj_geoms:
                    touching.add(a)
        return touching

    def _run(self, d: mujoco.MjData, seconds: float, hand: callable | None = None,
             ctrl: callable | None = None, watch: callable | None = None) -> None:
        n = max(1, int(round(seconds / self.config.timestep)))
        for k in range(n):
            s = (k + 1) / n
            if hand is not None:
                self._set_hand(d, hand(s))
            if ctrl is not None:
                d.ctrl[:] = ctrl(s)
            mujoco.mj_step(self.model, d)
            if watch is not None:
                watch(d)

    def _lowest_z(self, T: np.ndarray) -> float:
        return float(min((p @ T[:3, :3].T + T[:3, 3])[:, 2].min() for p in self.parts))

    # -- the two operations -------------------------------------------------------------------------------
    def grasp(self, T_base_object: np.ndarray, T_base_gripper: np.ndarray, opening: float, opening_cmd: float,
              rng: np.random.Generator | None = None) -> PhysicsGrasp:
        """Close the pads (from ``opening`` towards ``opening_cmd``) on the object resting at
        ``T_base_object`` with the hand at ``T_base_gripper``, then lift ``lift_height`` and hold."""
        c = self.config
        with self._lock:
            d = self._start(rng)
            Tg = np.asarray(T_base_gripper, dtype=np.float64)
            self._set_object(d, T_base_object)
            self._set_hand(d, Tg, teleport=True)
            self._set_pads(d, opening)
            mujoco.mj_forward(self.model, d)
            h0, h1 = opening / 2, max(opening_cmd, 0.0) / 2
            T_start = invert(Tg) @ np.asarray(T_base_object, dtype=np.float64)
            self._run(d, c.close_time, ctrl=lambda s: h0 + (h1 - h0) * s)
            self._run(d, 0.15)
            touching = self._pads_touching(d)
            if len(touching) < 2:
                self._run(d, 0.5)
                return PhysicsGrasp(False, "no_grip", self._width(d), None, self._object_pose(d), 0.0, None,
                                    "the pads closed without gripping the object "
                                    f"({len(touching)} of 2 pads touch it)")
            z0 = self._object_pose(d)[2, 3]
            up = np.eye(4)

            def lifted(s: float) -> np.ndarray:
                up[2, 3] = c.lift_height * _smooth(s)
                return up @ Tg
            self._run(d, c.lift_time, hand=lifted)
            self._run(d, c.hold_time)
            T_obj = self._object_pose(d)
            T_hand = lifted(1.0)
            rise = T_obj[2, 3] - z0
            T_go = invert(T_hand) @ T_obj
            turn = _rotation_deg(invert(T_start) @ T_go)
            if rise < 0.75 * c.lift_height or len(self._pads_touching(d)) < 2:
                width = self._width(d)
                # what is left hanging or wedged comes down where it lands once the pads open (the
                # orchestrator's next step after a failed grasp)
                w0, half_open = d.ctrl[0], self.spec.max_opening / 2
                self._run(d, c.open_time, ctrl=lambda s: w0 + (half_open - w0) * s)
                self._run(d, 0.8)
                return PhysicsGrasp(False, "slip", width, None, self._object_pose(d), turn, None,
                                    f"the object slid out of the pads while lifting (rose {rise * 1000:.0f} of "
                                    f"{c.lift_height * 1000:.0f} mm)")
            pads = tuple(float(d.qpos[a]) for a in self._pad_q)
            return PhysicsGrasp(True, "ok", self._width(d), T_go, T_obj, turn, pads,
                                f"holding {self._width(d) * 1000:.1f} mm between the pads; it turned "
                                f"{turn:.1f} deg in the hand")

    def set_down(self, T_base_gripper: np.ndarray, T_gripper_object: np.ndarray, pad_state: tuple[float, ...],
                 rng: np.random.Generator | None = None) -> PhysicsSetDown:
        """Open the pads holding the object at ``T_base_gripper @ T_gripper_object`` (``pad_state``: the
        pads' joints as ``grasp`` left them, so contact resumes exactly as it was), back the hand off and
        let the object come to rest. If the held object reaches below the table top, hand and object are
        raised until it touches it (the arm stops on contact) before the pads open."""
        c = self.config
        with self._lock:
            d = self._start(rng)
            Tg = np.asarray(T_base_gripper, dtype=np.float64).copy()
            T_obj = Tg @ T_gripper_object
            low = self._lowest_z(T_obj)
            if low < 0.0005:
                Tg[2, 3] += 0.0005 - low
                T_obj = Tg @ T_gripper_object
            self._set_object(d, T_obj)
            self._set_hand(d, Tg, teleport=True)
            for a, q in zip(self._pad_q, pad_state, strict=True):
                d.qpos[a] = q
            d.ctrl[:] = 0.0  # still squeezing, as it was carried
            mujoco.mj_forward(self.model, d)
            z_release = T_obj[2, 3]
            peak = [z_release]
            half_open = self.spec.max_opening / 2
            w0 = float(pad_state[0])

            def watch(dd: mujoco.MjData) -> None:
                peak[0] = max(peak[0], float(dd.qpos[self._obj_qpos + 2]))
            self._run(d, 0.05)
            peak[0] = float(d.qpos[self._obj_qpos + 2])
            self._run(d, c.open_time, ctrl=lambda s: w0 + (half_open - w0) * s, watch=watch)
            back = np.eye(4)

            def retreat(s: float) -> np.ndarray:
                back[0, 3] = -c.retreat * _smooth(s)
                return Tg @ back
            self._run(d, 0.3, hand=retreat, watch=watch)
            away = retreat(1.0)

            def up(s: float) -> np.ndarray:  # and up, clear of anything leaning on the pads
                T = away.copy()
                T[2, 3] += 0.15 * _smooth(s)
                return T
            self._run(d, 0.3, hand=up, watch=watch)
            settled = False
            for _ in range(int(np.ceil(c.settle_time / 0.1))):
                self._run(d, 0.1, watch=watch)
                v = d.qvel[self._obj_dof:self._obj_dof + 6]
                if np.linalg.norm(v[:3]) < 2e-3 and np.linalg.norm(v[3:]) < 2e-2:
                    settled = True
                    break
            T_end = self._object_pose(d)
            tilt = tilt_deg(T_end)
            toppled = tilt > c.topple_tilt_deg
            bounce = max(0.0, peak[0] - z_release)
            msg = (f"came to rest tilted {tilt:.0f} deg" + (" (toppled)" if toppled else "")
                   + f"; bounced {bounce * 1000:.1f} mm")
            return PhysicsSetDown(T_end, tilt, toppled, bounce, settled, msg)

    def sweeps_near(self, T_base_object: np.ndarray, T_from: np.ndarray, T_to: np.ndarray) -> bool:
        """Whether the pads, moving on the straight line from ``T_from`` to ``T_to``, come near the object
        resting at ``T_base_object`` (its bounding sphere grown by the pads' half diagonal): cheap, so the
        twin runs ``push`` only where a sweep can touch it."""
        s = self.spec
        reach = 0.5 * float(np.linalg.norm([s.pad_length, 2 * s.pad_thickness, s.pad_height])) + 0.005
        c = T_base_object[:3, :3] @ self._centre + T_base_object[:3, 3]
        a, b = np.asarray(T_from, float)[:3, 3], np.asarray(T_to, float)[:3, 3]
        ab = b - a
        t = float(np.clip((c - a) @ ab / (ab @ ab), 0.0, 1.0)) if ab @ ab > 0 else 0.0
        return float(np.linalg.norm(a + t * ab - c)) < self._radius + reach

    def push(self, T_base_object: np.ndarray, T_from: np.ndarray, T_to: np.ndarray, opening: float,
             rng: np.random.Generator | None = None) -> np.ndarray:
        """Where the object resting at ``T_base_object`` is once the hand, pads ``opening`` apart, has moved
        on a straight line from ``T_from`` to ``T_to`` at ``push_speed``: pushed, turned or tipped by the
        pads, or left where it was. A push continues the previous one's simulation (the object's motion
        carries on) when it starts where that one left hand and object; otherwise it starts at rest."""
        c = self.config
        with self._lock:
            Tf, Tt = np.asarray(T_from, float), np.asarray(T_to, float)
            To = np.asarray(T_base_object, float)
            sweep = self._sweep
            if sweep is not None and np.allclose(sweep[1], Tf, atol=1e-6) and np.allclose(sweep[2], To, atol=1e-6):
                d = sweep[0]
            else:
                d = self._start(rng)
                self._set_object(d, To)
                self._set_hand(d, Tf, teleport=True)
                self._set_pads(d, opening)
                mujoco.mj_forward(self.model, d)
            seconds = max(float(np.linalg.norm(Tt[:3, 3] - Tf[:3, 3])) / max(c.push_speed, 1e-6), c.timestep)

            def along(s: float) -> np.ndarray:
                T = Tt.copy()
                T[:3, 3] = Tf[:3, 3] + s * (Tt[:3, 3] - Tf[:3, 3])
                return T
            self._run(d, seconds, hand=along)
            T_end = self._object_pose(d)
            v = d.qvel[self._obj_dof:self._obj_dof + 6]
            moving = bool(self._pads_touching(d)) or np.linalg.norm(v[:3]) > 2e-3 or np.linalg.norm(v[3:]) > 2e-2
            still = np.linalg.norm(T_end[:3, 3] - To[:3, 3]) < 1e-4 and _rotation_deg(invert(To) @ T_end) < 0.05
            if not moving and still:
                self._sweep = None  # untouched: it stays exactly where it was (no resting jitter)
                return To.copy()
            self._sweep = (d, Tt.copy(), T_end.copy()) if moving else None
            return T_end

    def settle(self, T_base_object: np.ndarray, seconds: float = 1.0) -> np.ndarray:
        """Where an object put at ``T_base_object`` (e.g. hovering, or tilted) comes to rest on the table."""
        with self._lock:
            d = self._start(None)
            self._set_object(d, T_base_object)
            self._set_hand(d, make_transform(np.eye(3), [0.0, 0.0, 2.0]), teleport=True)  # pads far away
            self._set_pads(d, self.spec.max_opening)
            self._run(d, seconds)
            return self._object_pose(d)


def _rotation_deg(T: np.ndarray) -> float:
    """Rotation angle (deg) of a pose's rotation part."""
    return float(np.degrees(np.arccos(np.clip((np.trace(T[:3, :3]) - 1) / 2, -1.0, 1.0))))
