"""Frozen, validated configuration dataclasses for the crowd simulator.

All lengths are metres, times seconds, speeds m/s and force strengths are accelerations (m/s^2, i.e.
force per unit mass): the simulator multiplies them by the body mass before handing them to pymunk.
Defaults come from the literature cited on each field and run as they are.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any


def _positive(name: str, value: float) -> None:
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a finite positive number, got {value!r}")


def _non_negative(name: str, value: float) -> None:
    if not (math.isfinite(value) and value >= 0):
        raise ValueError(f"{name} must be a finite non-negative number, got {value!r}")


def _in_range(name: str, value: float, lo: float, hi: float) -> None:
    if not (math.isfinite(value) and lo <= value <= hi):
        raise ValueError(f"{name} must lie in [{lo}, {hi}], got {value!r}")


@dataclass(frozen=True)
class SocialForceParams:
    """Helbing–Molnár social force with an anisotropic exponential pedestrian repulsion.

    Driving term: (v0 e - v) / tau (Helbing & Molnár 1995, tau = 0.5 s).
    Pedestrian repulsion on i from j: A exp((r_i + r_j - d_ij) / B) n_ji w(phi), with the anisotropy
    w = lam + (1 - lam)(1 + cos phi) / 2 (Helbing et al. 2000 circular specification; lam < 1 weakens
    interactions from behind). A, B and lam are calibrated (scripts/calibrate_social_force.py, on seeds
    1000-1005, which the tests do not use) so that, with the default radii, the periodic one-way corridor
    follows Weidmann's (1993) fundamental diagram within 0.07 m/s at 0.5, 1 and 2 persons/m^2 (tested to
    0.10 m/s in tests/crowdsim/test_fundamental_diagram.py); of the grid points that do, these slow free
    walking in a sparse plaza least. B is close to Helbing–Molnár's sigma = 0.3 m. lam = 0.5 lets a
    faster walker push a slower one ahead along rather than queue behind it (the circular specification
    does not overtake); with lam = 0.3 such queues hold the corridor 0.09 m/s below Weidmann at 0.5/m^2.
    Wall repulsion: A_w exp((r_i - d) / B_w) along the wall normal, d the centre-to-wall distance
    (Helbing et al. 2000: A_w = 2000 N / 80 kg = 25 m/s^2, B_w = 0.08 m). Helbing–Molnár's
    (U0 / R) exp(-d / R) with U0 = 10 m^2/s^2, R = 0.2 m pushes 4 m/s^2 from each jamb of a 1 m door,
    more than the driving term, and blocks doors.
    """

    relaxation_time_s: float = 0.5
    desired_speed_mean_mps: float = 1.34
    desired_speed_std_mps: float = 0.26
    desired_speed_min_mps: float = 0.5
    desired_speed_max_mps: float = 2.0
    max_speed_factor: float = 1.3  # speeds are capped at this times the desired speed
    ped_strength_mps2: float = 3.0  # A
    ped_range_m: float = 0.32  # B
    anisotropy: float = 0.5  # lam in [0, 1]
    wall_strength_mps2: float = 25.0  # A_w
    wall_range_m: float = 0.08  # B_w
    cutoff_m: float = 3.0  # neighbour search radius for pedestrian and wall interactions
    arrival_radius_m: float = 0.3  # within this of the goal a pedestrian has arrived
    slowdown_radius_m: float = 1.0  # the desired speed ramps down linearly inside this distance
    fluctuation_mps2: float = 0.1  # std of a random acceleration per force step (Helbing–Molnár's fluctuations);
    # it breaks the exact symmetry of head-on encounters, which otherwise deadlock
    # a pedestrian whose goal is behind a wall aims this far off the wall's end, outside the corner
    # (`crowdsim.detour`; 0.6 m fixes people stuck behind corners, docs/decisions/crowdsim-group-walking.md); 0
    # (default until the benchmark's next suite version, so that every recorded episode stays as it was): straight
    # at the goal always
    detour_clearance_m: float = 0.0

    def __post_init__(self) -> None:
        for name in ("relaxation_time_s", "desired_speed_mean_mps", "ped_range_m", "wall_range_m",
                     "cutoff_m", "arrival_radius_m", "slowdown_radius_m", "desired_speed_max_mps"):
            _positive(name, getattr(self, name))
        for name in ("desired_speed_std_mps", "desired_speed_min_mps", "ped_strength_mps2",
                     "wall_strength_mps2", "fluctuation_mps2", "detour_clearance_m"):
            _non_negative(name, getattr(self, name))
        _in_range("anisotropy", self.anisotropy, 0.0, 1.0)
        if self.max_speed_factor < 1.0:
            raise ValueError(f"max_speed_factor must be >= 1, got {self.max_speed_factor}")
        if self.desired_speed_min_mps > self.desired_speed_max_mps:
            raise ValueError("desired_speed_min_mps must not exceed desired_speed_max_mps")


@dataclass(frozen=True)
class GroupForceParams:
    """Moussaïd et al. (2010) group terms, strengths as accelerations.

    gaze: -beta1 alpha v, alpha the head rotation (rad) beyond the vision half-angle needed to see the
    centre of mass of the other members; coherence: beta2 towards the group's centre of mass when farther
    than (n - 1) / 2 m; repulsion: beta3 away from each member closer than d0 (centre to centre).

    Catch-up (added here): +beta1' gamma min(|v|, |v_desired|) along the heading, gamma = max(pi - half-angle -
    angle, 0) (rad), the angle being that of the others' centre from the heading: the mirror image of the gaze
    term's alpha, so with the default 90 deg half-angle gamma is how far the others' centre lies ahead of
    abreast. With beta1' = beta1 a member who has fallen behind speeds up as much as one who has drawn ahead
    slows down, the symmetric along-track pull of Zanlungo et al.'s group potential (PRE 2014); with the gaze
    term alone a group is held to its slowest member and brakes on every perturbation, and pairs walked at 0.85
    and triples at 0.78 of their desired speed in a sparse plaza against 0.94 for people alone. Both terms fade
    linearly to zero as the others' centre comes within `gaze_fade_m` of the member (the middle of an abreast
    triple), where its direction is undefined. The calibration: scripts/calibrate_group_speed.py; the test:
    tests/crowdsim/test_fundamental_diagram.py.

    Rows (added here): groups above three walk in two rows, as sub-groups (Moussaïd et al. 2010,
    `groups.gaze_subgroups`), and each member looks mostly at its own row; `whole_group_gaze_share` of its gaze
    brake and catch-up push is directed at the whole group's other members instead, since members of a large group
    also turn to the other row to keep it together. 0: rows ignore each other, the front row never waits for the
    back one, and groups of 4-5 walked as fast as triples (0.08 m/s slower than people alone) and 5s only 0.12
    slower; 1: Moussaïd's model, everyone looks at the whole group, the front row brakes until the rows walk
    nearly abreast, and 4-5s walked 0.18-0.21 m/s slower (both with members repelling each other as strangers
    do, below). The share is calibrated so that groups of 4 and 5 slow down by Moussaïd's 0.04 m/s per member,
    0.12 and 0.16 m/s (`scripts/calibrate_group_speed.py --rows`, seeds 1000-1039: 0.130 and 0.145 at 0.6; it
    was 0.125 before members stopped repelling each other as strangers, and 4-5s then walked at -0.08/-0.12).
    Groups of up to three are one row and are not affected.

    Members tolerate each other (added here): `member_ped_repulsion_scale` multiplies the ordinary pedestrian
    (social-force) repulsion `SocialForceParams` between two members of the same group. Members of a group walk
    inside each other's personal zone, and in Moussaïd et al.'s (2010) group model their spacing is kept by the
    group repulsion term (beta3 within d0) alone; the strangers' repulsion between them pushed a lone pair to
    1.06 m apart against the coherence ramp, where real groups walk 0.74 m apart (median, UCY). 1: strangers'
    repulsion between members as well (the model before, bit for bit); 0: none (Moussaïd's), the default. With
    it, d0 = 0.6 m (was 0.8) sets the spacing: in-group pairs of the realistic-v1 preset walk 0.75 m apart
    (median; 1.10 before) and 0.29 m/s relative speed (0.35; UCY 0.14), scripts/measure_group_geometry.py on
    seeds 1000-1003; tests/crowdsim/test_group_geometry.py.
    """

    gaze_strength: float = 4.0  # beta1, 1/s (multiplies alpha [rad] * v [m/s])
    coherence_strength_mps2: float = 3.0  # beta2
    repulsion_strength_mps2: float = 1.0  # beta3
    repulsion_distance_m: float = 0.6  # d0, m: the members' spacing (see member_ped_repulsion_scale)
    vision_half_angle_deg: float = 90.0
    catch_up_strength: float = 4.0  # 1/s, the same as beta1: the pull is symmetric
    gaze_fade_m: float = 0.4
    whole_group_gaze_share: float = 0.6  # dimensionless, in [0, 1]: rows of groups above three (see above)
    member_ped_repulsion_scale: float = 0.0  # dimensionless, in [0, 1]: strangers' repulsion between members

    def __post_init__(self) -> None:
        for name in ("gaze_strength", "coherence_strength_mps2", "repulsion_strength_mps2", "catch_up_strength"):
            _non_negative(name, getattr(self, name))
        _positive("repulsion_distance_m", self.repulsion_distance_m)
        _positive("gaze_fade_m", self.gaze_fade_m)
        _in_range("whole_group_gaze_share", self.whole_group_gaze_share, 0.0, 1.0)
        _in_range("member_ped_repulsion_scale", self.member_ped_repulsion_scale, 0.0, 1.0)
        _in_range("vision_half_angle_deg", self.vision_half_angle_deg, 0.0, 180.0)


@dataclass(frozen=True)
class GroupConfig:
    """How groups are drawn and which group events happen.

    Group sizes follow a zero-truncated Poisson with rate `size_poisson_rate`, capped at `max_size`
    (lambda = 1.1 puts about two thirds of people in groups, mostly pairs; FIELD_NOTES). A group of
    size n walks at a shared desired speed drawn from N(1.34 - 0.02 (n - 1), 0.26) m/s, clipped. The drop is
    calibrated (scripts/calibrate_group_speed.py) so that the walking speeds groups reach at low density fall by
    Moussaïd et al.'s (2010, Fig. 2) 0.04 m/s per member: the group terms slow them a little on top.
    Events are Poisson processes per group, rates in 1/s: `leave_rate_hz` makes one member of a group
    of two or more leave (new goal, new singleton label); `merge_rate_hz` makes a group join the
    nearest other group within `merge_distance_m` walking the same way (shared goal and label).
    """

    size_poisson_rate: float = 1.1
    max_size: int = 5
    speed_drop_per_member_mps: float = 0.02
    formation_spacing_m: float = 0.75  # lateral distance between neighbours in the abreast formation
    leave_rate_hz: float = 0.0
    merge_rate_hz: float = 0.0
    merge_distance_m: float = 4.0

    def __post_init__(self) -> None:
        _non_negative("size_poisson_rate", self.size_poisson_rate)
        if not isinstance(self.max_size, int) or self.max_size < 1:
            raise ValueError(f"max_size must be an integer >= 1, got {self.max_size!r}")
        for name in ("speed_drop_per_member_mps", "leave_rate_hz", "merge_rate_hz"):
            _non_negative(name, getattr(self, name))
        _positive("formation_spacing_m", self.formation_spacing_m)
        _positive("merge_distance_m", self.merge_distance_m)

    def size_probabilities(self) -> list[float]:
        """Probability of each group size 1..max_size (zero-truncated Poisson, tail folded into max)."""
        lam = self.size_poisson_rate
        if lam == 0:
            return [1.0] + [0.0] * (self.max_size - 1)
        raw = [lam**k / math.factorial(k) for k in range(1, self.max_size + 1)]
        norm = math.exp(lam) - 1.0
        probs = [p / norm for p in raw]
        probs[-1] += max(0.0, 1.0 - sum(probs))
        return probs


@dataclass(frozen=True)
class BehaviourConfig:
    """What people do besides walking in formation (`crowdsim.behaviours`). Rates are per group (or per
    member) in 1/s, drawn once per recording step; a rate of 0 turns a behaviour off.

    - Variation inside a group: each member's desired speed is the group's plus N(0, member_speed_std_mps),
      and each lateral spacing of the walking formation is scaled by 1 + N(0, member_spacing_std).
    - Stops: a walking group stops (`stop_rate_hz`) in one of the scenario's stop areas or at one of its points
      of interest (a shop window, a notice board: `poi_share` of the stops), stands in an F-formation, members
      on a circle around a shared o-space, neighbours `fformation_spacing_m` apart, centre to centre (Kendon
      1990; the spacing lies in Hall's personal-distance range 0.45–1.2 m), for an exponential time with mean
      `stop_mean_s` (at least `stop_min_s`), then walks on to where it was going. Stationary groups are a large
      part of real crowds (Yi, Li & Wang, CVPR 2015, stationary crowd groups in a station concourse).
    - Meeting and parting at a stop: a single walking within `join_distance_m` of a standing group's centre
      joins it (`join_rate_hz` per standing group; it takes the group's label, place and destination), and a
      member of a standing group of 2+ leaves on its own (`part_rate_hz` per member; a new label).
    - Strangers who walk close: an arriving single enters, with probability `stranger_companion_prob`, right
      beside or behind the group that entered last from the same entrance, heading for the same exit at a
      similar speed, so that distance alone does not reveal who is together. It then keeps pace with that group
      (`stranger_follow_gain_per_s`, 1/s; 0: it walks at its own speed and drifts away): each recording step its
      desired speed becomes the group's walking speed plus the gain times how far it has fallen behind the
      along-track gap it entered with, the speed adaptation of a pedestrian following another (Lemercier et al.,
      "Realistic following behaviors for crowd simulation", Computer Graphics Forum 2012, measured followers
      matching the leader's speed within about a second). It lets go when the group stops or leaves, or the gap has
      changed by more than 3 m.
    """

    member_speed_std_mps: float = 0.05
    member_spacing_std: float = 0.1
    stop_rate_hz: float = 0.0
    poi_share: float = 0.5
    stop_mean_s: float = 40.0
    stop_min_s: float = 8.0
    fformation_spacing_m: float = 0.9
    join_rate_hz: float = 0.0
    join_distance_m: float = 3.0
    part_rate_hz: float = 0.0
    stranger_companion_prob: float = 0.0
    stranger_follow_gain_per_s: float = 0.5

    def __post_init__(self) -> None:
        for name in ("member_speed_std_mps", "member_spacing_std", "stop_rate_hz", "join_rate_hz",
                     "part_rate_hz", "stop_min_s", "stranger_follow_gain_per_s"):
            _non_negative(name, getattr(self, name))
        for name in ("stop_mean_s", "fformation_spacing_m", "join_distance_m"):
            _positive(name, getattr(self, name))
        _in_range("poi_share", self.poi_share, 0.0, 1.0)
        _in_range("stranger_companion_prob", self.stranger_companion_prob, 0.0, 1.0)
        _in_range("member_spacing_std", self.member_spacing_std, 0.0, 0.5)


@dataclass(frozen=True)
class RobotSlot:
    """The external agent slot. `visible` makes pedestrians repel from the robot like from a person."""

    visible: bool = True
    radius_m: float = 0.3

    def __post_init__(self) -> None:
        _positive("radius_m", self.radius_m)


@dataclass(frozen=True)
class SimConfig:
    """Top-level simulator configuration.

    The recording step (dataset frame) is `record_dt_s`; social forces are re-evaluated every
    `force_dt_s` and pymunk integrates contacts with `physics_substeps` sub-steps per force step
    (sub-step = force_dt_s / physics_substeps <= 0.05 s).
    """

    scenario: str = "plaza"
    n_pedestrians: int = 40
    record_dt_s: float = 0.4  # the ETH/UCY step; twin of predictor.ethucy.STEP_S (tests/test_shared_facts.py)
    force_dt_s: float = 0.1
    physics_substeps: int = 4
    radius_min_m: float = 0.22
    radius_max_m: float = 0.28
    mass_kg: float = 80.0
    social: SocialForceParams = field(default_factory=SocialForceParams)
    group_forces: GroupForceParams = field(default_factory=GroupForceParams)
    groups: GroupConfig = field(default_factory=GroupConfig)
    behaviour: BehaviourConfig = field(default_factory=BehaviourConfig)
    robot: RobotSlot = field(default_factory=RobotSlot)
    scenario_options: tuple[tuple[str, float], ...] = ()  # scenario-specific overrides (name, value)

    def __post_init__(self) -> None:
        if not isinstance(self.n_pedestrians, int) or self.n_pedestrians < 1:
            raise ValueError(f"n_pedestrians must be an integer >= 1, got {self.n_pedestrians!r}")
        if self.groups.max_size > self.n_pedestrians:
            raise ValueError(
                f"groups.max_size={self.groups.max_size} is larger than the crowd "
                f"(n_pedestrians={self.n_pedestrians})"
            )
        for name in ("record_dt_s", "force_dt_s", "mass_kg", "radius_min_m", "radius_max_m"):
            _positive(name, getattr(self, name))
        if self.radius_min_m > self.radius_max_m:
            raise ValueError("radius_min_m must not exceed radius_max_m")
        if not isinstance(self.physics_substeps, int) or self.physics_substeps < 1:
            raise ValueError(f"physics_substeps must be an integer >= 1, got {self.physics_substeps!r}")
        if self.physics_dt_s > 0.05 + 1e-12:
            raise ValueError(f"physics sub-step {self.physics_dt_s:.3f} s exceeds 0.05 s; raise physics_substeps")
        ratio = self.record_dt_s / self.force_dt_s
        if abs(ratio - round(ratio)) > 1e-9:
            raise ValueError("record_dt_s must be an integer multiple of force_dt_s")
        from crowdsim.scenarios import check_options  # lazy: scenarios is the larger module

        check_options(self.scenario, dict(self.scenario_options))

    @property
    def physics_dt_s(self) -> float:
        return self.force_dt_s / self.physics_substeps

    @property
    def force_steps_per_record(self) -> int:
        return round(self.record_dt_s / self.force_dt_s)

    def option(self, name: str, default: float) -> float:
        return dict(self.scenario_options).get(name, default)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)
