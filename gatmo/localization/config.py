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
    """Monte Carlo localization parameters (the ROS AMCL / Nav2 name of each in its
    description)."""

    # filter
    min_particles: int = Field(
        500, ge=1,
        description="fewest particles KLD-sampling keeps at a resampling (ROS: min_particles)",
    )
    max_particles: int = Field(
        2000, ge=1,
        description="most particles KLD-sampling keeps at a resampling, and the number spread "
        "around an initial pose or over the map by global localization (ROS: max_particles)",
    )
    kld_err: float = Field(
        0.05, gt=0, lt=1,
        description="KLD-sampling's bound on the error (Kullback-Leibler distance) between the "
        "particle set and the true distribution, over bins of 0.5 m x 0.5 m x 10 deg; smaller "
        "keeps more particles (ROS 1: kld_err; Nav2: pf_err)",
    )
    kld_z: float = Field(
        0.99, gt=0,
        description="KLD-sampling's upper standard normal quantile for 1 - p, p the probability "
        "that the error stays below kld_err; larger keeps more particles (ROS 1: kld_z; "
        "Nav2: pf_z)",
    )
    update_min_d_m: float = Field(
        0.25, ge=0,
        description="a filter update (motion, sensor update, resampling) runs once the odometry "
        "x or y (odom frame) has changed by more than this since the last one; scans in between "
        "only carry the estimate forward by odometry (ROS: update_min_d)",
    )
    update_min_a_rad: float = Field(
        0.2, ge=0,
        description="a filter update also runs once the odometry heading has changed by more "
        "than this since the last one (ROS: update_min_a)",
    )
    resample_interval: int = Field(
        1, ge=1,
        description="number of sensor updates between resamplings (ROS: resample_interval)",
    )
    selective_resampling: bool = Field(
        False,
        description="skip a due resampling while the effective sample size 1 / sum(w^2) is "
        "above half the number of particles (ROS: selective_resampling)",
    )
    recovery_alpha_slow: float = Field(
        0.0, ge=0, le=1,
        description="rate of w_slow, the long-term exponential average of the measurement "
        "likelihood (see recovery_per_beam); at each resampling every particle is replaced by a "
        "random one (free cell, any heading) with probability max(0, 1 - w_fast / w_slow), "
        "and 0 here and in recovery_alpha_fast turns this off (ROS: recovery_alpha_slow)",
    )
    recovery_alpha_fast: float = Field(
        0.0, ge=0, le=1,
        description="rate of w_fast, the short-term average (see recovery_alpha_slow); unlike "
        "AMCL, an injection does not reset the averages, so random particles keep coming while "
        "w_fast < w_slow (ROS: recovery_alpha_fast)",
    )
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
    laser_model: LaserModel = Field(
        "likelihood_field",
        description="laser sensor model: likelihood_field scores a particle 1 + sum over the "
        "beams of pz^3 (AMCL's), likelihood_field_prob the product of the beams' pz (and can "
        "skip beams, do_beamskip), beam ray-casts each beam in the map (beam_ray_caster) "
        "(ROS: laser_model_type)",
    )
    beam_ray_caster: RayCaster = Field(
        "march",
        description=(
            "ray caster of the beam model (laser_model: beam; not an AMCL parameter): "
            "'march' exact, jumps on the distance transform; 'dda' exact, cell by cell; "
            "'lut' range table, 5-10x faster, median error 5 mm, built once per map "
            "(seconds, tens of MB)"
        ),
    )
    z_hit: float = Field(
        0.5, ge=0, le=1,
        description="weight of the hit term of a beam's likelihood, a Gaussian (sigma_hit_m) in "
        "the distance from the beam's endpoint to the nearest obstacle, or for the beam model "
        "from the ray-cast range (ROS 1: laser_z_hit; Nav2: z_hit)",
    )
    z_short: float = Field(
        0.05, ge=0, le=1,
        description="beam model only: weight of the term for a reading shorter than the "
        "ray-cast range (an obstacle not in the map), exponential in the range with rate "
        "lambda_short (ROS 1: laser_z_short; Nav2: z_short)",
    )
    z_max: float = Field(
        0.05, ge=0, le=1,
        description="beam model only: weight of the term added for a reading at or beyond the "
        "maximum range (the likelihood-field models drop such readings) (ROS 1: laser_z_max; "
        "Nav2: z_max)",
    )
    z_rand: float = Field(
        0.5, ge=0, le=1,
        description="weight of the random-reading term of a beam's likelihood, z_rand / "
        "range_max for a reading below the maximum range, all models (ROS 1: laser_z_rand; "
        "Nav2: z_rand)",
    )
    sigma_hit_m: float = Field(
        0.2, gt=0,
        description="standard deviation of the hit term's Gaussian (z_hit); 3 sigma_hit_m is "
        "also the obstacle distance beyond which an unknown cell is unmapped "
        "(skip_unmapped_beams) (ROS 1: laser_sigma_hit; Nav2: sigma_hit)",
    )
    lambda_short: float = Field(
        0.1, gt=0,
        description="beam model only: rate [1/m] of the short-reading term's exponential "
        "(z_short) (ROS 1: laser_lambda_short; Nav2: lambda_short)",
    )
    laser_likelihood_max_dist_m: float = Field(
        2.0, gt=0,
        description="the likelihood field's distances to the nearest obstacle are clipped at "
        "this: a beam ending farther from every obstacle, or off the map, counts as this far "
        "(ROS: laser_likelihood_max_dist)",
    )
    laser_min_range_m: float | None = Field(
        None, description="None: use the scan's own range_min (AMCL's -1.0)"
    )
    laser_max_range_m: float | None = Field(
        None, description="None: use the scan's own range_max (AMCL's -1.0)"
    )
    max_beams: int = Field(
        60, ge=2,
        description="beams weighed per scan: every k-th beam of the scan's n, k = (n - 1) // "
        "(max_beams - 1), so about this many, evenly spaced (ROS 1: laser_max_beams; "
        "Nav2: max_beams)",
    )
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
    do_beamskip: bool = Field(
        False,
        description="likelihood_field_prob, once the filter has converged (converged_dist_m): "
        "leave out of the weighing the beams that too few particles explain (likely obstacles "
        "not in the map) (ROS: do_beamskip)",
    )
    beam_skip_distance_m: float = Field(
        0.5, gt=0,
        description="do_beamskip: a particle explains a beam whose endpoint lies within this "
        "distance of an obstacle (ROS: beam_skip_distance)",
    )
    beam_skip_threshold: float = Field(
        0.3, ge=0, le=1,
        description="do_beamskip: a beam is kept when at least this fraction of the particles "
        "explain it (ROS: beam_skip_threshold)",
    )
    beam_skip_error_threshold: float = Field(
        0.9, ge=0, le=1,
        description="do_beamskip: when more than this fraction of the beams would be left out, "
        "none is (the scan is weighed in full) (ROS: beam_skip_error_threshold)",
    )
    # odometry
    odom_model: OdomModel = Field(
        "diff-corrected",
        description="odometry motion model: diff and omni are ROS 1's originals, which use a "
        "variance as the noise's standard deviation; diff-corrected and omni-corrected take its "
        "square root, as Nav2 does (ROS 1: odom_model_type; Nav2: robot_model_type)",
    )
    alpha1: float = Field(
        0.2, ge=0,
        description="odometry noise: weight of the squared rotation in the variance of the "
        "rotation noise (diff models), or of the translation and strafe noise (omni models) "
        "(ROS 1: odom_alpha1; Nav2: alpha1)",
    )
    alpha2: float = Field(
        0.2, ge=0,
        description="odometry noise: weight of the squared translation in the variance of the "
        "rotation noise (ROS 1: odom_alpha2; Nav2: alpha2)",
    )
    alpha3: float = Field(
        0.2, ge=0,
        description="odometry noise: weight of the squared translation in the variance of the "
        "translation noise (ROS 1: odom_alpha3; Nav2: alpha3)",
    )
    alpha4: float = Field(
        0.2, ge=0,
        description="odometry noise: weight of the squared rotation in the variance of the "
        "translation noise (diff models), or of the rotation noise (omni models) "
        "(ROS 1: odom_alpha4; Nav2: alpha4)",
    )
    alpha5: float = Field(
        0.2, ge=0,
        description="omni models only: weight of the squared translation in the variance of "
        "the strafe (sideways) noise (ROS 1: odom_alpha5; Nav2: alpha5)",
    )
    odom_jump_m: float = Field(
        1.0, gt=0,
        description="not an AMCL parameter: an odometry step between two consecutive scans "
        "longer than this is a jump (a reset, a slip, or the wheels catching up after a "
        "stall): see odom_jump_motion_weight",
    )
    odom_jump_rad: float = Field(
        1.0, gt=0,
        description="not an AMCL parameter: a heading change between the odometry poses of two "
        "consecutive scans beyond this is a jump, as odom_jump_m is",
    )
    odom_jump_motion_weight: float = Field(
        0.5, ge=0, le=1,
        description="not an AMCL parameter: at a jump the filter holds two hypotheses, the "
        "step was real motion (the particles follow it, with this prior mass) or none (a "
        "cloud of max_particles/2 around the last estimate with 4x the initial covariance, "
        "the rest); the next scan decides between them. 0: the second only, the filter "
        "restarts around the last estimate; 1: the first only, as AMCL takes every step. An "
        "estimate off the map restarts globally",
    )
    # initial pose
    initial_pose_xytheta: tuple[float, float, float] | None = Field(
        None,
        description="initial pose (x [m], y [m], heading [rad], map frame) the particles start "
        "around, a Gaussian with the initial_cov_* variances; None: none. `gatmo localize`, "
        "`run` and `compare` start there unless given --initial-pose or --global (ROS 1: "
        "initial_pose_x / _y / _a; Nav2: initial_pose x / y / yaw with set_initial_pose)",
    )
    initial_cov_xx_m2: float = Field(
        0.25, ge=0,
        description="variance of x of the particles spread around an initial pose (map frame), "
        "times 4 after an odometry jump (ROS 1: initial_cov_xx)",
    )
    initial_cov_yy_m2: float = Field(
        0.25, ge=0,
        description="variance of y of the particles spread around an initial pose (map frame), "
        "times 4 after an odometry jump (ROS 1: initial_cov_yy)",
    )
    initial_cov_aa_rad2: float = Field(
        (3.141592653589793 / 12) ** 2, ge=0,
        description="variance of the heading of the particles spread around an initial pose, "
        "times 4 after an odometry jump (ROS 1: initial_cov_aa)",
    )
    global_localization_on_start: bool = Field(
        False,
        description="not an AMCL parameter (read under this name from a params file): without "
        "initial_pose_xytheta, spread the particles over the map's free cells, any heading, "
        "when the localizer is built; otherwise the first scan does it",
    )
    converged_dist_m: float = Field(
        0.5, gt=0,
        description="the filter has converged when every particle lies within this of the "
        "particles' mean in x and in y; convergence enables do_beamskip and the "
        "min_explained_beam_fraction gate (AMCL's pf->dist_threshold, fixed at 0.5 there)",
    )
    seed: int = Field(
        0,
        description="not an AMCL parameter: seed of the random generator of a localizer built "
        "without one; `gatmo localize` (seed 0), `run` and `compare` (the stack's seed) pass "
        "their own, so there it has no effect",
    )

    @model_validator(mode="after")
    def _check(self) -> AmclConfig:
        if self.min_particles > self.max_particles:
            raise ValueError(
                f"min_particles ({self.min_particles}) > max_particles ({self.max_particles})"
            )
        return self
