"""Simulator configuration (one validated model, sub-models per part)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from gatmo.config import GatmoModel


class LaserConfig(GatmoModel):
    beams: int = Field(181, ge=2, le=4000)
    fov_deg: float = Field(180.0, gt=0, le=360)
    max_range_m: float = Field(4.0, gt=0)
    noise_std_m: float = Field(0.01, ge=0)
    spurious_short_prob: float = Field(0.005, ge=0, le=1)
    forward_offset_m: float = Field(0.1, ge=0, description="laser ahead of the base centre")


class OdomConfig(GatmoModel):
    """Thrun's sample_motion_model_odometry noise plus a per-run scale bias."""

    alpha1: float = Field(0.05, ge=0)
    alpha2: float = Field(0.01, ge=0)
    alpha3: float = Field(0.05, ge=0)
    alpha4: float = Field(0.01, ge=0)
    scale_bias_std: float = Field(0.02, ge=0)


class PeopleConfig(GatmoModel):
    count_per_run: int = Field(2, ge=0)
    min_speed_mps: float = Field(0.5, gt=0)
    max_speed_mps: float = Field(1.2, gt=0)

    @model_validator(mode="after")
    def _ordered(self) -> PeopleConfig:
        if self.min_speed_mps > self.max_speed_mps:
            raise ValueError("min_speed_mps must be <= max_speed_mps")
        return self


class RearrangeConfig(GatmoModel):
    """Per piece and run: moved elsewhere / shifted and turned in place / removed / put back
    where it stood in an earlier layout (``return_prob``: chairs go back to their desks); plus
    adds."""

    move_prob: float = Field(0.15, ge=0, le=1)
    shift_prob: float = Field(0.15, ge=0, le=1)
    remove_prob: float = Field(0.03, ge=0, le=1)
    return_prob: float = Field(0.0, ge=0, le=1)
    add_count: int = Field(1, ge=0)
    shift_min_m: float = Field(0.2, ge=0)
    shift_max_m: float = Field(1.0, ge=0)

    @model_validator(mode="after")
    def _consistent(self) -> RearrangeConfig:
        if self.move_prob + self.shift_prob + self.remove_prob + self.return_prob > 1.0 + 1e-9:
            raise ValueError("move_prob + shift_prob + remove_prob + return_prob must be <= 1")
        if self.shift_min_m > self.shift_max_m:
            raise ValueError("shift_min_m must be <= shift_max_m")
        return self


class RobotConfig(GatmoModel):
    speed_mps: float = Field(0.4, gt=0)
    max_turn_rate_rps: float = Field(0.8, gt=0)
    scan_rate_hz: float = Field(10.0, gt=0)
    duration_s: float = Field(60.0, gt=0)


class SimConfig(GatmoModel):
    """All simulator parameters; ``for_preset`` gives each world's defaults."""

    preset: Literal["hall", "office"] = "hall"
    laser: LaserConfig = Field(default_factory=LaserConfig)
    odom: OdomConfig = Field(default_factory=OdomConfig)
    people: PeopleConfig = Field(default_factory=PeopleConfig)
    rearrange: RearrangeConfig = Field(default_factory=RearrangeConfig)
    robot: RobotConfig = Field(default_factory=RobotConfig)
    resolution_m: float = Field(0.05, gt=0)

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
