"""Parameter sets of the simulation: every field's default, unit and source (facts.md, the paper,
or "not measured": a guess, docs/lab-measurements.md).

The defaults here are the shipped model; ``config/robot.yaml`` and
``config/sim.yaml`` hold only what a deployment changes (empty as shipped),
and ``docs/sim.md``'s parameter tables are generated from these classes. The
dimensions and rates other packages share come from puzzlebot_common
(``geometry.RobotGeometry``, ``hardware``).

``RobotParams`` (config/robot.yaml, key ``robot``): the robot body, wheels,
casters, front opening, anchor holder and side connectors.
``AnchorParams`` (config/robot.yaml, key ``anchor``): the soft anchor's
three-bar linkage and its measured force profile.
``SimParams`` (config/sim.yaml, key ``sim``): stepping, solver, world and the
injectable actuator/measurement effects.
``WorldParams`` (config/sim.yaml, key ``world``): dimensions of the worlds
(defined in puzzlebot_common.stages, which the MPC reads too).
``AnchorRestParams`` (config/sim.yaml, key ``anchor_rest``): when a resting
anchor may be frozen to its robot (a speed shortcut, docs/sim.md).

Frames: a robot's ``base_link`` is at the body centre, x forward, z up; the
body's bottom is ``ground_clearance`` above the floor. The anchor frame is at
the centre of the anchor's base, axes parallel to the robot's at rest (so its
head points to -x).
"""

import math
from dataclasses import dataclass, fields
from typing import Tuple

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.geometry import RobotGeometry
from puzzlebot_common.hardware import CONTROL_PERIOD, MOCAP_RATE
from puzzlebot_common.params import from_mapping, require_positive
from puzzlebot_common.stages import WorldParams  # noqa: F401  (the worlds' dimensions: one home, shared with the MPC)

#: Bullet's collision margin for URDF shapes [m]. A box half-extent or a
#: cylinder radius below it is inflated to it in contacts, so every collision
#: feature must be at least this large (``urdf.check_features``); the chamfer
#: and keel checks below use it too.
URDF_MARGIN = 0.001


def _require_nonnegative(obj, names, where):
    for name in names:
        if not getattr(obj, name) >= 0:
            raise ConfigError("%s.%s: must be >= 0, got %r" % (where, name, getattr(obj, name)))


@dataclass(frozen=True)
class RobotParams:
    """Simulated PuzzleBot body (config/robot.yaml, ``robot``)."""

    # body
    body_side: float = RobotGeometry.body_side  # m, square body, origin at its centre
    body_height: float = 0.045       # m
    body_mass: float = 0.068         # kg (whole robot incl. wheels' share)
    ground_clearance: float = 0.003  # m, body bottom above the floor (not measured)
    body_friction: float = 0.3       # -, body shell (PLA) against the floor and the stage (not measured)
    bottom_chamfer: float = 0.0      # m, 45-degree chamfer along the front and back edges of the body's
    #                                   bottom (0 = square edges; 0 or >= 2 mm, Bullet's margin; not measured)
    top_chamfer: float = 0.0         # m, the same along the top front and back edges: how far two coupled
    #                                   robots fold concave before their tops meet (docs/sim.md; not measured)
    side_fillet: float = 0.0         # m, radius of the four vertical corner edges (0 = square; 0 or >= 2 mm;
    #                                   a printed body's edges are rounded; not measured)
    # wheels (pilots: two pairs at x = +/-pilot_wheel_x)
    wheel_radius: float = 0.010      # m
    wheel_width: float = 0.003       # m
    wheel_y: float = 0.020           # m, wheel centre distance from the body axis
    wheel_mass: float = 0.002        # kg each
    wheel_inertia: float = 3.0e-6    # kg m^2, about the axle incl. the gear motor's reflected rotor inertia
    wheel_friction: float = 1.0      # -, lateral friction coefficient with the floor
    wheel_max_torque: float = 0.0025  # N m per wheel (0.5 N total push at 10 mm radius)
    wheel_max_speed: float = 20.0    # rad/s (0.2 m/s rim speed, the hardware v_max)
    wheel_no_load_speed: float = 0.0  # rad/s, DC-motor torque-speed line (docs/sim.md): the torque driving a
    #                                   wheel falls linearly from wheel_max_torque at stall to 0 at this speed
    #                                   (back-EMF, modelled as axle damping wheel_max_torque / this speed);
    #                                   0 = off, ideal speed control up to wheel_max_torque at any speed;
    #                                   20 = the no-load speed at the hardware's v_max
    pilot_wheel_x: float = 0.013     # m, pilot robots' wheel pairs at x = +/-pilot_wheel_x (not measured)
    # ball casters (non-pilot robots), frictionless
    caster_radius: float = 0.005     # m
    caster_x: float = 0.018          # m, casters at (+/-caster_x, 0)
    caster_clearance: float = 0.0005  # m, caster bottom above the floor: the wheels carry the weight
    wheel_base: float = RobotGeometry.wheel_base  # m, track used to split (v, w) into wheel speeds
    # front opening: a mouth between two lips, the slits (a cavity) behind, the battery box behind that
    opening_z: float = -0.010        # m, height of the opening's (and the anchor's) centre line above base_link
    mouth_width: float = 0.0085      # m, gap between the lips
    mouth_height: float = 0.009      # m, height of mouth and slits
    lip_depth: float = 0.002         # m, thickness of the lips (x); their inner ends are half-cylinders
    slit_width: float = 0.024        # m, full width of the cavity behind the lips
    cavity_depth: float = 0.0145     # m, front face to the battery box
    lock_height: float = 0.005       # m, lock slot (not measured): a recess in the slits' ceiling behind a sill,
    #                                   into which the head rises when the anchor robot tips over an edge (edge lock)
    lock_width: float = 0.012        # m, width of the lock slot (not measured)
    lock_sill: float = 0.003         # m, solid ceiling between the lips and the lock slot (not measured)
    battery_x: float = 0.020         # m, battery box (x, y, z) inside the body
    battery_y: float = 0.026         # m
    battery_z: float = 0.020         # m
    # anchor holder: a pocket in the back face, closed by a retaining wall with a slot
    holder_depth: float = 0.015      # m, pocket depth incl. the retaining wall (5 mm anchor travel)
    holder_wall: float = 0.002       # m, retaining wall thickness
    holder_width: float = 0.0084     # m, pocket width (y): anchor base's lateral play +/-0.2 mm
    holder_height: float = 0.0082    # m, pocket height (z)
    holder_slot_width: float = 0.0050  # m, slot in the retaining wall: the anchor's yaw play
    holder_slot_height: float = 0.0045  # m, height of the slot: the bar rests on its bottom (pitch play)
    # side connectors for rigid (bridge) coupling: knob on the left (+y), hole on the right (-y)
    knob_radius: float = RobotGeometry.knob_radius  # m
    knob_height: float = 0.010       # m, vertical cylinder, half sunk into the left side
    knob_z: float = 0.008            # m, knob centre height above the body centre
    hole_width: float = 0.010        # m (x)
    hole_depth: float = 0.005        # m (y), into the right side
    hole_height: float = 0.012       # m (z), centred at knob_z
    # the knob gives way: the lab prints the body in TPU (NinjaFlex), whose side flexes when a
    # neighbour's side presses the knob; modelled as a plunger on a prismatic joint along +y that a
    # spring pushes out. Not measured yet (docs/lab-measurements.md, item 10)
    knob_travel: float = 0.0045      # m, how far a pressed knob goes into its side (0: a rigid knob; not measured)
    knob_spring_force: float = 0.1   # N, the spring's force pushing the knob out (the drive pushes 0.5 N; not measured)
    knob_mass: float = 0.002         # kg, the knob plunger

    @classmethod
    def from_dict(cls, data, where="robot"):
        return from_mapping(cls, data, where)

    def check(self, where="robot"):
        names = [f.name for f in fields(self)]
        nonneg = ["ground_clearance", "body_friction", "wheel_friction", "caster_x", "caster_clearance",
                  "pilot_wheel_x", "wheel_no_load_speed", "bottom_chamfer", "top_chamfer", "knob_travel",
                  "side_fillet"]
        require_positive(self, [n for n in names if n not in nonneg and n != "opening_z"], where)
        _require_nonnegative(self, nonneg, where)
        h, half_h = self.body_side / 2.0, self.body_height / 2.0
        if self.wheel_y + self.wheel_width / 2 > h:
            raise ConfigError("%s: wheels (wheel_y + wheel_width/2 = %.4f m) stick out of the body "
                              "(body_side/2 = %.4f m)" % (where, self.wheel_y + self.wheel_width / 2, h))
        if not self.mouth_width < self.slit_width < self.body_side:
            raise ConfigError("%s: need mouth_width (%g) < slit_width (%g) < body_side (%g)"
                              % (where, self.mouth_width, self.slit_width, self.body_side))
        if self.lip_depth >= self.cavity_depth or self.cavity_depth + self.battery_x >= self.body_side:
            raise ConfigError("%s: need lip_depth < cavity_depth and cavity_depth + battery_x < body_side"
                              % where)
        if self.lock_width > self.slit_width or self.lip_depth + self.lock_sill >= self.cavity_depth:
            raise ConfigError("%s: the lock slot must fit above the slits (lock_width <= slit_width, "
                              "lip_depth + lock_sill < cavity_depth)" % where)
        if abs(self.opening_z) + self.mouth_height / 2 + self.lock_height >= half_h:
            raise ConfigError("%s: the lock slot does not fit under the body's top" % where)
        if abs(self.opening_z) + max(self.mouth_height, self.holder_height) / 2 >= half_h:
            raise ConfigError("%s: opening/holder (opening_z = %g) do not fit in the body height" % (where, self.opening_z))
        if self.holder_slot_width > self.holder_width or self.holder_slot_height > self.holder_height:
            raise ConfigError("%s: the holder slot must not be larger than the pocket" % where)
        if self.holder_wall >= self.holder_depth or self.holder_depth + self.cavity_depth >= self.body_side:
            raise ConfigError("%s: holder_depth/holder_wall do not fit the body" % where)
        self._check_chamfers(where)
        if self.caster_radius * 2 > self.body_side / 2 + self.ground_clearance:
            raise ConfigError("%s.caster_radius: too large for the body" % where)
        if 0.0 < self.wheel_no_load_speed < self.wheel_max_speed:
            raise ConfigError("%s.wheel_no_load_speed (%g rad/s): below wheel_max_speed (%g rad/s), the wheels "
                              "could never reach their speed limit (0 turns the torque-speed line off)"
                              % (where, self.wheel_no_load_speed, self.wheel_max_speed))
        if self.wheel_radius < self.ground_clearance:
            raise ConfigError("%s: wheel_radius must exceed ground_clearance" % where)
        if self.knob_travel > self.knob_radius + 1e-9:
            raise ConfigError("%s.knob_travel (%g m): a knob cannot go further into its side than its radius "
                              "(%g m)" % (where, self.knob_travel, self.knob_radius))
        if self.knob_radius * 2 > self.hole_width or self.knob_radius > self.hole_depth + 1e-9 \
                or self.knob_height > self.hole_height:
            raise ConfigError("%s: the knob (r=%g, h=%g) must fit the hole (%g x %g x %g)"
                              % (where, self.knob_radius, self.knob_height, self.hole_width, self.hole_depth,
                                 self.hole_height))

    def _check_chamfers(self, where):
        """Chamfers are 0 or at least 2 mm (Bullet's margin) and leave the opening, lock slot, holder
        and side connectors whole."""
        half_h = self.body_height / 2.0
        port = max(self.mouth_height, self.holder_height) / 2.0
        sides = self.body_side / 2.0 - max(self.hole_width / 2.0, self.knob_radius)      # knob and hole at x = 0
        room = {"bottom_chamfer": min(half_h + self.opening_z - port, sides),            # below mouth / holder
                "top_chamfer": min(half_h - self.opening_z - max(self.mouth_height / 2.0 + self.lock_height, port),
                                   sides)}
        if 0.0 < self.side_fillet < 2 * URDF_MARGIN - 1e-12:
            raise ConfigError("%s.side_fillet: %.1f mm is below Bullet's 2 mm collision margin (use 0 for square "
                              "edges)" % (where, 1e3 * self.side_fillet))
        corner_room = self.body_side / 2.0 - max(self.hole_width / 2.0, self.knob_radius, self.slit_width / 2.0,
                                                 self.holder_width / 2.0)
        if self.side_fillet >= corner_room:
            raise ConfigError("%s.side_fillet: %.1f mm would cut into the side connectors, the slits or the holder "
                              "(must be below %.1f mm)" % (where, 1e3 * self.side_fillet, 1e3 * corner_room))
        for name, limit in room.items():
            c = getattr(self, name)
            if 0.0 < c < 2 * URDF_MARGIN - 1e-12:
                raise ConfigError("%s.%s: %.1f mm is below Bullet's 2 mm collision margin (use 0 for a "
                                  "square edge)" % (where, name, 1e3 * c))
            if c >= limit:
                raise ConfigError("%s.%s: %.1f mm would cut into the front opening, the anchor holder or the "
                                  "side connectors (must be below %.1f mm)" % (where, name, 1e3 * c, 1e3 * limit))

    @property
    def body_centre_height(self):
        """Height of the body centre (base_link origin) above the floor at rest [m]."""
        return self.ground_clearance + self.body_height / 2.0

    @property
    def v_max(self):
        """Rim speed at the wheel speed limit [m/s] (the hardware v_max)."""
        return self.wheel_max_speed * self.wheel_radius

    @property
    def wheel_back_emf_damping(self):
        """Axle damping [N m s/rad] that gives the DC-motor line (0 when the line is off).

        With the velocity motor saturated at ``wheel_max_torque`` the net
        drive torque is ``wheel_max_torque * (1 - speed / wheel_no_load_speed)``;
        braking gets the stall torque plus the damping, as a DC motor does.
        """
        return self.wheel_max_torque / self.wheel_no_load_speed if self.wheel_no_load_speed > 0.0 else 0.0

    @property
    def push_force(self):
        """Largest force the two (non-pilot) driven wheels can push with [N]."""
        return 2.0 * self.wheel_max_torque / self.wheel_radius


def _profile(values, where, name):
    if not isinstance(values, (list, tuple)) or len(values) < 2 or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in values):
        raise ConfigError("%s.%s: expected a list of at least two finite numbers, got %r" % (where, name, values))
    return tuple(float(v) for v in values)


@dataclass(frozen=True)
class AnchorParams:
    """The soft anchor as a rigid linkage (config/robot.yaml, ``anchor``).

    Links: base (in the holder) -- neck joint (pitch: the TPU's bending) --
    middle bar with the head (a diamond) -- two side bars (barbs) on revolute
    joints about z at the head, pointing back toward the base at
    ``barb_angle`` from the bar. The barbs' restoring torque follows the
    measured force profile (``*_profile_mm`` / ``*_profile_n``: probe
    displacement [mm] -> force [N] on the whole anchor, both barbs),
    ``forward`` when pushed in (barbs fold), ``backward`` when pulled
    (barbs flare); see puzzlebot_sim/anchor.py for the mapping.
    """

    base_radius: float = 0.004       # m, the base: a ball in the holder (free yaw, one contact) with a collar
    collar_width: float = 0.004      # m, the collar: a box as long as the ball, this wide ...
    collar_height: float = 0.002     # m, ... and this high; its flat ends square the anchor up against the
    #                                  holder's walls
    keel_height: float = 0.0         # m, a keel through the ball (as long as it, this high; 0 = none), 2 mm wide
    #                                  (2 x URDF_MARGIN: rounded across, so it stops pitch, not yaw): the pocket's
    #                                  floor and ceiling and the retaining wall stop its pitch; 7.5 mm holds it to the
    #                                  paper's 0.1 rad but stops the wiggle (docs/sim.md)
    roll_limit: float = 0.4          # rad, the holder stops the anchor's roll about its own x axis beyond this
    #                                  (puzzlebot_sim/roll_stop.py; 0 = no stop)
    base_mass: float = 0.0010        # kg
    length: float = 0.0243           # m, base centre to head tip (13.3 mm out of the back face when pushed in)
    neck_x: float = 0.0075           # m, base centre to the neck joint
    bar_width: float = 0.003         # m
    bar_height: float = 0.004        # m
    head_width: float = 0.0055       # m, diamond head (also its length)
    head_height: float = 0.006       # m
    head_mass: float = 0.0004        # kg, bar + head
    hinge_back: float = 0.0005       # m, barb hinge along the head's rear edge from its side corner
    barb_length: float = 0.007       # m
    barb_thickness: float = 0.002    # m
    barb_height: float = 0.004       # m
    barb_tip_radius: float = 0.001   # m, rounded tip: a vertical cylinder ending the barb
    barb_angle: float = 0.65         # rad, rest angle of a barb from the middle bar
    barb_mass: float = 0.001         # kg each (heavier than TPU: solver stability)
    inertia_radius: float = 0.01     # m, radius of gyration floor of the anchor's links (solver conditioning)
    barb_fold_limit: float = 0.03    # rad, smallest barb angle (folded against the bar)
    barb_flip_limit: float = 3.1     # rad, largest barb angle (flipped forward, pulled out)
    barb_servo_rate: float = 20.0    # 1/s, velocity servo gain pulling a barb back to rest
    barb_min_torque: float = 2.0e-5  # N m, restoring torque floor (returns the barb to rest)
    barb_post_snap_ratio: float = 0.45  # -, share of its torque at the profile's end a barb keeps past it
    #                                     (snapped through, flipping forward); 0 = drop to barb_min_torque
    neck_max_torque: float = 0.01    # N m, pitch stiffness limit of the neck (TPU bending)
    neck_servo_rate: float = 20.0    # 1/s
    neck_limit: float = 1.5          # rad, +/- neck bending range
    friction: float = 0.3            # -, anchor base in the holder
    barb_friction: float = 0.0       # -, barbs on the opening (the measured profile already holds friction)
    head_friction: float = 0.3       # -, bar and head (TPU) on the opening
    # the measured force profile (paper, "Characterization of Anchors")
    forward_profile_mm: Tuple[float, ...] = (0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 4.5, 5.0)
    #                                  mm, probe displacement, pushed into an opening
    forward_profile_n: Tuple[float, ...] = (0.0, 0.06, 0.10, 0.13, 0.15, 0.16, 0.165, 0.165, 0.16, 0.15, 0.14)
    #                                  N, force on the whole anchor there (max < 0.2 N)
    backward_profile_mm: Tuple[float, ...] = (0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 4.5, 5.0)
    #                                  mm, probe displacement, pulled out
    backward_profile_n: Tuple[float, ...] = (0.0, 0.05, 0.11, 0.18, 0.26, 0.34, 0.42, 0.51, 0.60, 0.66, 0.70)
    #                                  N, force on the whole anchor there (0.6 N at 4 mm)

    @classmethod
    def from_dict(cls, data, where="anchor"):
        return from_mapping(cls, data, where)

    def check(self, where="anchor"):
        for name in ("forward_profile_mm", "forward_profile_n", "backward_profile_mm", "backward_profile_n"):
            object.__setattr__(self, name, _profile(getattr(self, name), where, name))
        scalar = [f.name for f in fields(self) if not f.name.endswith(("_mm", "_n"))]
        nonneg = ("friction", "barb_friction", "head_friction", "barb_min_torque", "hinge_back",
                  "barb_post_snap_ratio", "keel_height", "roll_limit")
        _require_nonnegative(self, nonneg, where)
        require_positive(self, [n for n in scalar if n not in nonneg], where)
        for kind in ("forward", "backward"):
            mm, n = getattr(self, kind + "_profile_mm"), getattr(self, kind + "_profile_n")
            if len(mm) != len(n):
                raise ConfigError("%s: %s_profile_mm and %s_profile_n differ in length (%d, %d)"
                                  % (where, kind, kind, len(mm), len(n)))
            if mm[0] != 0.0 or any(b <= a for a, b in zip(mm, mm[1:])):
                raise ConfigError("%s.%s_profile_mm: must start at 0 and increase" % (where, kind))
            if any(v < 0 for v in n):
                raise ConfigError("%s.%s_profile_n: forces must be >= 0" % (where, kind))
        if self.barb_post_snap_ratio > 1.0:
            raise ConfigError("%s.barb_post_snap_ratio (%g): a snapped beam carries at most its peak torque (<= 1)"
                              % (where, self.barb_post_snap_ratio))
        if not self.barb_fold_limit < self.barb_angle < math.pi / 2 < self.barb_flip_limit <= math.pi:
            raise ConfigError("%s: need barb_fold_limit < barb_angle < pi/2 < barb_flip_limit <= pi" % where)
        if self.neck_x + self.bar_width > self.length - self.head_width:
            raise ConfigError("%s: neck_x leaves no bar between neck and head" % where)
        if self.roll_limit >= math.pi / 2:
            raise ConfigError("%s.roll_limit (%g rad): 0 (no stop) or below pi/2, where the anchor lies on its side"
                              % (where, self.roll_limit))
        if self.barb_tip_radius < self.barb_thickness / 2:
            raise ConfigError("%s.barb_tip_radius: must be >= barb_thickness/2 (the tip is the contact)" % where)
        if self.hinge_back >= self.head_width / 2:
            raise ConfigError("%s.hinge_back: must be < head_width/2" % where)

    @property
    def mass(self):
        return self.base_mass + self.head_mass + 2 * self.barb_mass

    def check_fits(self, robot, where="anchor"):
        """Raise ConfigError unless the anchor fits the robot's holder and opening."""
        d = 2 * self.base_radius
        if d > min(robot.holder_width, robot.holder_height) or d <= min(robot.holder_slot_width,
                                                                          robot.holder_slot_height):
            raise ConfigError("%s.base_radius: the base ball (%.1f mm) must fit the holder pocket and not pass "
                              "its slot" % (where, 1e3 * d))
        if self.collar_width >= robot.holder_width or self.collar_height >= d:
            raise ConfigError("%s: the collar must be narrower than the pocket and lower than the ball" % where)
        if self.keel_height and not 2 * URDF_MARGIN <= self.keel_height < robot.holder_height:
            raise ConfigError("%s.keel_height: 0 (no keel) or from %g m up to below the holder pocket's height "
                              "(%g m)" % (where, 2 * URDF_MARGIN, robot.holder_height))
        if self.bar_width >= robot.holder_slot_width or self.bar_height >= robot.holder_slot_height:
            raise ConfigError("%s: the bar (%g x %g m) does not pass the holder slot" % (where, self.bar_width,
                                                                                   self.bar_height))
        if self.head_width >= robot.mouth_width:
            raise ConfigError("%s.head_width: the head (%g m) does not pass the mouth (%g m)"
                              % (where, self.head_width, robot.mouth_width))
        if robot.holder_depth - robot.holder_wall <= d:
            raise ConfigError("%s: the holder pocket leaves the base no travel" % where)


@dataclass(frozen=True)
class SimParams:
    """Sim node / SimWorld options (config/sim.yaml, ``sim``)."""

    physics_rate: int = 200          # Hz, Bullet fixed step, a multiple of pose_rate (accuracy vs speed: docs/sim.md)
    pose_rate: int = MOCAP_RATE      # Hz, vicon topics, tf and /clock (the lab's Vicon rate)
    pairs_rate: int = 10             # Hz, /puzzlebot/sim/physical_pairs; pose_rate is a multiple of it
    joint_state_rate: int = 10       # Hz, /joint_states (wheels, anchor neck and barbs; robot_state_publisher)
    diagnostics_period: float = 1.0  # s (wall) between /diagnostics messages (real-time factor, overruns)
    real_time_factor: float = 0.0    # 1 = wall-clock pace, 0 = as fast as possible
    cmd_timeout: float = 0.5         # s (sim time): a robot without a fresh cmd_vel stops
    sync_topic: str = ""             # lockstep with a controller: at each sync_period wait for a stamped message
    #                                  on this topic (empty: off; sim.launch: the MPC's solver_stats)
    sync_period: float = CONTROL_PERIOD  # s, the controller's period (the MPC's dt)
    sync_timeout: float = 10.0       # s (wall) to wait for the controller before going on
    sync_startup_timeout: float = 60.0  # s (wall) to wait for the controller's first message
    sync_cmd_timeout: float = 10.0   # s (wall), then for the cmd_vel of every robot the controller commanded the
    #                                  period before (cmd_vel and the sync message travel on separate connections;
    #                                  as long as sync_timeout: a stalled machine must not make a run differ)
    world: str = "flat"              # flat | step | gap (puzzlebot_sim.worlds)
    gui: bool = False                # the PyBullet GUI (default: DIRECT, no window)
    seed: int = 0                    # mocap noise and dropouts
    solver_iterations: int = 15      # Bullet constraint solver iterations per step
    tilted_solver_iterations: int = 100  # ... while any robot is tilted by more than tilt_threshold (edges, hanging)
    tilt_threshold: float = 0.15     # rad
    erp: float = 0.2                 # contact error reduction (per step)
    anchors: bool = True             # give every robot its soft anchor
    # injectable effects (off by default)
    actuator_model: str = ""         # path of a model.yaml (puzzlebot_common/effects.py); empty = none
    wheel_imbalance: float = 0.0     # -, right wheel speed x (1 + k), left x (1 - k)
    mocap_position_std: float = 0.0  # m, Gaussian noise on published positions
    mocap_yaw_std: float = 0.0       # rad, Gaussian noise on published yaw
    mocap_dropout: float = 0.0       # -, probability that a pose message is dropped
    mocap_heading_offset: float = 0.0  # rad, marker frame yaw - body yaw (added to the model's)

    @classmethod
    def from_dict(cls, data, where="sim"):
        return from_mapping(cls, data, where)

    def check(self, where="sim"):
        require_positive(self, ["physics_rate", "pose_rate", "pairs_rate", "joint_state_rate", "diagnostics_period",
                                "cmd_timeout", "sync_period",
                                "sync_timeout", "sync_startup_timeout", "sync_cmd_timeout", "solver_iterations", "erp",
                                "tilted_solver_iterations", "tilt_threshold"], where)
        if self.real_time_factor < 0:
            raise ConfigError("%s.real_time_factor: must be >= 0 (0 = as fast as possible)" % where)
        if self.physics_rate % self.pose_rate:
            raise ConfigError("%s: physics_rate (%d Hz) must be an integer multiple of pose_rate (%d Hz)"
                              % (where, self.physics_rate, self.pose_rate))
        if self.pose_rate % self.pairs_rate:
            raise ConfigError("%s: pose_rate (%d Hz) must be an integer multiple of pairs_rate (%d Hz)"
                              % (where, self.pose_rate, self.pairs_rate))
        if self.pose_rate % self.joint_state_rate:
            raise ConfigError("%s: pose_rate (%d Hz) must be an integer multiple of joint_state_rate (%d Hz)"
                              % (where, self.pose_rate, self.joint_state_rate))
        ticks = self.sync_period * self.pose_rate
        if abs(ticks - round(ticks)) > 1e-6:
            raise ConfigError("%s: sync_period (%g s) must be a whole number of pose periods (1/%d s)"
                              % (where, self.sync_period, self.pose_rate))
        _require_nonnegative(self, ["mocap_position_std", "mocap_yaw_std"], where)
        if not 0.0 <= self.mocap_dropout < 1.0:
            raise ConfigError("%s.mocap_dropout: must be in [0, 1), got %r" % (where, self.mocap_dropout))
        if not -1.0 < self.wheel_imbalance < 1.0:
            raise ConfigError("%s.wheel_imbalance: must be in (-1, 1), got %r" % (where, self.wheel_imbalance))
        if self.erp > 1.0:
            raise ConfigError("%s.erp: must be in (0, 1]" % where)


@dataclass(frozen=True)
class AnchorRestParams:
    """Resting anchors (config/sim.yaml, ``anchor_rest``): a numerical shortcut, see docs/sim.md.

    An anchor that has rested in its holder for ``settle_time`` while nothing
    can touch it is frozen to its robot: its bodies leave the Bullet world,
    its weight stays on the robot, and its pose follows the robot at the
    pose where it rested. It is put back (woken) as soon as another robot or
    anchor comes within ``clearance`` of it, the robot tilts, the terrain
    under it changes, or the robot's velocity changes by more than
    ``max_dv`` / ``max_dw`` within one ``check_period``. Interacting anchors
    (coupling, pull-outs, wiggles, edges) are therefore always simulated in
    full; a resting one costs almost nothing.
    """

    enabled: bool = True             # freeze resting anchors (false: every anchor is always simulated)
    clearance: float = 0.02          # m, nearest other robot or anchor that keeps an anchor awake
    settle_time: float = 0.25        # s, time at rest in the holder before an anchor is frozen
    check_period: float = 0.02       # s, period of the rest/wake tests (a whole number of physics steps)
    max_dv: float = 0.02             # m/s, robot velocity change within one check period that wakes it
    max_dw: float = 0.3              # rad/s, robot yaw-rate change within one check period that wakes it
    max_tilt: float = 0.05           # rad, robot tilt from level above which anchors stay awake
    max_rel_speed: float = 0.002     # m/s, anchor speed relative to its robot counted as rest
    max_rel_rate: float = 0.05       # rad/s, anchor (and joint) angular rate relative to its robot counted as rest
    max_joint_angle: float = 0.02    # rad, neck and barbs this close to straight/rest count as rest

    @classmethod
    def from_dict(cls, data, where="anchor_rest"):
        return from_mapping(cls, data, where)

    def check(self, where="anchor_rest"):
        require_positive(self, [f.name for f in fields(self) if f.name != "enabled"], where)
