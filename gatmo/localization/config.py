"""The localizer's configuration: every AMCL parameter, with units in the names.

Defaults are Nav2's (``nav2_amcl``); :mod:`gatmo.localization.params` maps ROS 1 and Nav2
parameter files onto this model (ROS 1 files get ROS 1 defaults).
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from gatmo.config import GatmoModel

OdomModel = Literal["diff", "diff-corrected", "omni", "omni-corrected"]
LaserModel = Literal["likelihood_field", "likelihood_field_prob", "beam"]
RayCaster = Literal["march", "lut", "dda"]


class AmclConfig(GatmoModel):
    """Monte Carlo localization parameters (AMCL names in the comments)."""

    # filter
    min_particles: int = Field(500, ge=1)  # min_particles
    max_particles: int = Field(2000, ge=1)  # max_particles
    kld_err: float = Field(0.05, gt=0, lt=1)  # kld_err / pf_err
    kld_z: float = Field(0.99, gt=0)  # kld_z / pf_z (upper standard normal quantile)
    update_min_d_m: float = Field(0.25, ge=0)  # update_min_d
    update_min_a_rad: float = Field(0.2, ge=0)  # update_min_a
    resample_interval: int = Field(1, ge=1)  # resample_interval
    selective_resampling: bool = False
    recovery_alpha_slow: float = Field(0.0, ge=0, le=1)
    recovery_alpha_fast: float = Field(0.0, ge=0, le=1)
    recovery_per_beam: bool = Field(
        True,
        description="not an AMCL parameter: the recovery averages (w_slow / w_fast) take the "
        "measurement likelihood per beam (the geometric mean over the beams weighed). The "
        "likelihood of a scan is a product over its beams, and their number changes from scan "
        "to scan (max-range beams drop out: 5 to 35 of 60 in a hall with a 4 m laser), so the "
        "raw average falls with every beam added and, driving towards a wall, injected 80 % "
        "random particles into a robot tracked to 0.1 m; false = AMCL")
    recovery_max_unmapped_fraction: float = Field(
        0.1, ge=0, le=1,
        description="not an AMCL parameter, with recovery on (recovery_alpha_slow/fast) and "
        "skip_unmapped_beams: an update that left out more than this fraction of its beams as "
        "ending in unmapped space neither updates w_slow / w_fast nor injects random "
        "particles. By a door out of the map or beyond it the mapped beams are few and their "
        "likelihood drops without the robot being lost, and particles injected then lock onto "
        "look-alike places of the map while the robot is outside it; 1 = AMCL")
    min_ess_fraction: float = Field(
        0.0, ge=0, le=1,
        description="not an AMCL parameter: when one update's weights would leave fewer than "
        "this fraction of the particles effective (a wide cloud under a sharp sensor model, "
        "e.g. the first update after an initial pose), the log-likelihoods are tempered "
        "(scaled by the largest factor <= 1 that keeps it), so the cloud narrows over a few "
        "updates instead of collapsing onto whichever particle fits best; 0 = off (AMCL)")
    # laser
    laser_model: LaserModel = "likelihood_field"
    beam_ray_caster: RayCaster = Field(
        "march",
        description=(
            "ray caster of the beam model (laser_model: beam; not an AMCL parameter): "
            "'march' exact, jumps on the distance transform; 'dda' exact, cell by cell; "
            "'lut' range table, 5-10x faster, median error 5 mm, built once per map "
            "(seconds, tens of MB)"
        ),
    )
    z_hit: float = Field(0.5, ge=0, le=1)
    z_short: float = Field(0.05, ge=0, le=1)
    z_max: float = Field(0.05, ge=0, le=1)
    z_rand: float = Field(0.5, ge=0, le=1)
    sigma_hit_m: float = Field(0.2, gt=0)
    lambda_short: float = Field(0.1, gt=0)
    laser_likelihood_max_dist_m: float = Field(2.0, gt=0)
    laser_min_range_m: float | None = Field(
        None, description="None: use the scan's own range_min (AMCL's -1.0)"
    )
    laser_max_range_m: float | None = Field(
        None, description="None: use the scan's own range_max (AMCL's -1.0)"
    )
    max_beams: int = Field(60, ge=2)
    skip_unmapped_beams: bool = Field(
        True,
        description=(
            "likelihood-field models (not an AMCL parameter): leave out the beams that end in "
            "unmapped space (an unknown cell beyond 3 sigma_hit of every obstacle, or off the "
            "map) for more than half of the particles; AMCL (false) scores them as misses, "
            "which pulls the particles towards the map when the robot drives out of it"
        ),
    )
    min_mapped_beam_fraction: float = Field(
        0.5, ge=0, le=1,
        description=(
            "with skip_unmapped_beams: a scan with fewer mapped beams than this fraction of its "
            "valid beams is not weighed at all (the robot looks mostly into unmapped space; "
            "the particles move by odometry alone)"
        ),
    )
    min_explained_beam_fraction: float = Field(
        0.0, ge=0, le=1,
        description=(
            "likelihood_field_prob (not an AMCL parameter): once the filter has converged, a "
            "scan of which fewer than this fraction of the beams are explained by the map (the "
            "hit term of a beam's likelihood above its random term, for the best tenth of the "
            "particles) is not weighed: the particles coast on odometry. Where the furniture "
            "in view has all moved, weighing such a scan pulls the particles onto whatever "
            "alignment of old and new furniture exists. For at most max_coast_m of travel: "
            "beyond it scans are weighed again as AMCL does (a lost filter sees unexplained "
            "scans too, and must be able to recover). 0: off (AMCL)"
        ),
    )
    explained_at: Literal["best_tenth", "prediction"] = Field(
        "best_tenth",
        description=(
            "where min_explained_beam_fraction tests the beams: best_tenth, for the best tenth "
            "of the particles; prediction, at the filter's estimate carried by odometry to "
            "this scan (the pose it publishes without the update). A cloud that has grown "
            "particles on a wrong alignment of old and new furniture has a best tenth that "
            "explains the scan. Measured on tuning hall seeds 300-305 (2026-11-27, threshold "
            "0.5, both localizers): the full stack's ATE 0.149 -> 0.43 m; a filter already "
            "0.7 m off, confident, sees every scan unexplained at its prediction and coasts "
            "where weighing would have brought it back"
        ),
    )
    max_coast_m: float = Field(
        3.0, gt=0, description="longest odometry-only stretch min_explained_beam_fraction allows"
    )
    segment_balanced: bool = Field(
        False,
        description=(
            "likelihood_field_prob (not an AMCL parameter): the scan is cut into segments "
            "where neighbouring beams' ranges jump by more than segment_jump_m, and a "
            "segment of more than segment_max_beams beams counts as that many (each beam's "
            "log-likelihood weighed down alike), so one long surface cannot outvote the "
            "other things in view. In a hall where a 4 m laser sees three or four pieces, one "
            "moved piece seen from close by has more beams than the rest together and pulls "
            "the filter along with it"
        ),
    )
    segment_max_beams: int = Field(5, ge=1, description="see segment_balanced")
    segment_jump_m: float = Field(0.3, gt=0, description="see segment_balanced")
    do_beamskip: bool = False
    beam_skip_distance_m: float = Field(0.5, gt=0)
    beam_skip_threshold: float = Field(0.3, ge=0, le=1)
    beam_skip_error_threshold: float = Field(0.9, ge=0, le=1)
    # odometry
    odom_model: OdomModel = "diff-corrected"
    alpha1: float = Field(0.2, ge=0)
    alpha2: float = Field(0.2, ge=0)
    alpha3: float = Field(0.2, ge=0)
    alpha4: float = Field(0.2, ge=0)
    alpha5: float = Field(0.2, ge=0)
    odom_jump_m: float = Field(1.0, gt=0, description="one-step odometry jump treated as reset")
    odom_jump_rad: float = Field(1.0, gt=0)
    # initial pose
    initial_pose_xytheta: tuple[float, float, float] | None = None
    initial_cov_xx_m2: float = Field(0.25, ge=0)
    initial_cov_yy_m2: float = Field(0.25, ge=0)
    initial_cov_aa_rad2: float = Field((3.141592653589793 / 12) ** 2, ge=0)
    global_localization_on_start: bool = False
    converged_dist_m: float = Field(0.5, gt=0)  # pf->dist_threshold
    seed: int = 0

    @model_validator(mode="after")
    def _check(self) -> AmclConfig:
        if self.min_particles > self.max_particles:
            raise ValueError(
                f"min_particles ({self.min_particles}) > max_particles ({self.max_particles})"
            )
        return self
