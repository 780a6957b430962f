"""Simulator configuration (one validated model, sub-models per part)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from gatmo.config import GatmoModel


class LaserConfig(GatmoModel):
    beams: int = Field(181, ge=2, le=4000, description="beams per scan, evenly over fov_deg")
    fov_deg: float = Field(
        180.0, gt=0, le=360, description="field of view, centred straight ahead")
    max_range_m: float = Field(
        4.0, gt=0, description="the laser's reach: a beam that hits nothing reads this")
    noise_std_m: float = Field(
        0.01, ge=0, description="standard deviation of the gaussian noise added to each "
        "return of a beam that hit something")
    spurious_short_prob: float = Field(
        0.005, ge=0, le=1, description="probability per beam of a spurious short reading "
        "(its range times a uniform 0.05-1)")
    forward_offset_m: float = Field(0.1, ge=0, description="laser ahead of the base centre")


class OdomConfig(GatmoModel):
    """Thrun's sample_motion_model_odometry noise plus a per-run scale bias."""

    alpha1: float = Field(
        0.05, ge=0, description="rotation noise from rotation: each turn's variance gets "
        "alpha1 times its square (Thrun's alpha1, as AMCL reads it)")
    alpha2: float = Field(
        0.01, ge=0, description="rotation noise from translation: each turn's variance gets "
        "alpha2 times the squared distance [rad^2/m^2]")
    alpha3: float = Field(
        0.05, ge=0, description="translation noise from translation: the distance's variance "
        "gets alpha3 times its square")
    alpha4: float = Field(
        0.01, ge=0, description="translation noise from rotation: the distance's variance gets "
        "alpha4 times the sum of the squared turns [m^2/rad^2]")
    scale_bias_std: float = Field(
        0.02, ge=0, description="per run, translation and rotation are each multiplied by "
        "1 + N(0, scale_bias_std) (a wheel calibration error: systematic drift)")
    stall_rate_per_min: float = Field(
        0.0, ge=0, description="stalls per minute of the run: the reported odometry holds "
        "still for stall_s, then catches up with the whole motion in one step (MIT CSAIL's "
        "wheels do this inside turns); 0: none")
    stall_s: float = Field(
        1.5, gt=0, description="how long each stall holds the odometry still [s]")


class PeopleConfig(GatmoModel):
    count_per_run: int = Field(
        2, ge=0, description="people walking in each run (one with no clear start is dropped)")
    min_speed_mps: float = Field(
        0.5, gt=0, description="each person walks at a constant speed drawn uniformly between "
        "min_speed_mps and max_speed_mps")
    max_speed_mps: float = Field(
        1.2, gt=0, description="fastest walking speed (see min_speed_mps)")

    @model_validator(mode="after")
    def _ordered(self) -> PeopleConfig:
        if self.min_speed_mps > self.max_speed_mps:
            raise ValueError("min_speed_mps must be <= max_speed_mps")
        return self


class RearrangeConfig(GatmoModel):
    """Per piece and run: moved elsewhere / shifted and turned in place / removed / put back
    where it stood in an earlier layout (``return_prob``: chairs go back to their desks); plus
    adds."""

    move_prob: float = Field(
        0.15, ge=0, le=1, description="probability a piece is moved to a new free place, "
        "with a random yaw")
    shift_prob: float = Field(
        0.15, ge=0, le=1, description="probability a piece is shifted by shift_min_m to "
        "shift_max_m in a random direction and turned by up to 60 deg")
    remove_prob: float = Field(
        0.03, ge=0, le=1, description="probability a piece is removed")
    return_prob: float = Field(
        0.0, ge=0, le=1, description="probability a piece is put back at one of its poses in "
        "earlier layouts more than 0.2 m from where it stands (with none, it stays)")
    add_count: int = Field(
        1, ge=0, description="new pieces (new ids, random labels) placed in each run's layout")
    shift_min_m: float = Field(0.2, ge=0, description="shortest shift (shift_prob)")
    shift_max_m: float = Field(1.0, ge=0, description="longest shift (shift_prob)")

    @model_validator(mode="after")
    def _consistent(self) -> RearrangeConfig:
        if self.move_prob + self.shift_prob + self.remove_prob + self.return_prob > 1.0 + 1e-9:
            raise ValueError("move_prob + shift_prob + remove_prob + return_prob must be <= 1")
        if self.shift_min_m > self.shift_max_m:
            raise ValueError("shift_min_m must be <= shift_max_m")
        return self


class RobotConfig(GatmoModel):
    speed_mps: float = Field(
        0.4, gt=0, description="top forward speed: the robot drives at speed_mps times "
        "cos(heading error)^4 towards the next waypoint, so it nearly turns in place at corners")
    max_turn_rate_rps: float = Field(
        0.8, gt=0, description="turn rate limit [rad/s]: the robot turns at twice its heading "
        "error, clipped to this")
    scan_rate_hz: float = Field(
        10.0, gt=0, description="scans per second; the robot and people are moved one scan "
        "period at a time")
    duration_s: float = Field(
        60.0, gt=0, description="length of each run: duration_s * scan_rate_hz scans")


class SimConfig(GatmoModel):
    """All simulator parameters; ``for_preset`` gives each world's defaults."""

    preset: Literal["hall", "office"] = Field(
        "hall", description="the world: hall (furniture dominates) or office (walls "
        "dominate); simulate_scenario sets it to the preset it builds")
    laser: LaserConfig = Field(default_factory=LaserConfig,
                               description="the laser scanner")
    odom: OdomConfig = Field(default_factory=OdomConfig,
                             description="the odometry's noise")
    people: PeopleConfig = Field(default_factory=PeopleConfig,
                                 description="the people walking in each run")
    rearrange: RearrangeConfig = Field(default_factory=RearrangeConfig,
                                       description="how the furniture changes before each run")
    robot: RobotConfig = Field(default_factory=RobotConfig,
                               description="the robot's motion along its route, and run length")
    resolution_m: float = Field(
        0.05, gt=0, description="cell side of the static map (map.yaml), rasterized from the "
        "layout before any rearrangement (L0)")

    @classmethod
    def for_preset(cls, name: str) -> SimConfig:
        """Defaults for a preset: ``hall`` (short-range laser, furniture dominates) or ``office``
        (walls dominate, 10 m laser)."""
        if name == "office":
            return cls(preset="office", laser=LaserConfig(max_range_m=10.0),
                       rearrange=RearrangeConfig(move_prob=0.2, shift_prob=0.2),
                       robot=RobotConfig(duration_s=90.0))
        if name == "hall":
            return cls(preset="hall")
        from gatmo.errors import ConfigError

        raise ConfigError(f"unknown preset {name!r}: hall | office", field="preset")
