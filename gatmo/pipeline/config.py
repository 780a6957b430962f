"""The full stack's configuration: one validated model per component, saved with every run."""

from __future__ import annotations

import math
from pathlib import Path

from pydantic import Field

from gatmo.config import GatmoModel, dump_model, load_model
from gatmo.localization.config import AmclConfig
from gatmo.maps.mapping import RenderConfig
from gatmo.objects.config import GatmoConfig
from gatmo.pipeline.stack import FusionConfig
from gatmo.scanmatch.odometry import IcpConfig
from gatmo.scanmatch.posegraph import GraphConfig


class StackConfig(GatmoModel):
    """amcl: localizer; gatmo: object map; icp: scan matcher; fusion: offset resets."""

    amcl: AmclConfig = Field(default_factory=AmclConfig, description="the localizer (AMCL)")
    gatmo: GatmoConfig = Field(default_factory=GatmoConfig,
                               description="GATMO: the object map")
    icp: IcpConfig = Field(default_factory=IcpConfig,
                           description="the scan matcher (odometry by ICP)")
    fusion: FusionConfig = Field(default_factory=FusionConfig,
                                 description="how localizer, scan matcher and GATMO work together "
                                 "(offset resets, published pose, masks, relocalization)")
    seed: int = Field(0, description="seed of the localizers' random draws; over several "
                      "logs, log k (from 0) uses seed + k")


class MapBuildConfig(GatmoModel):
    """``gatmo map build``: icp: the scan-matching odometry; graph: keyframes, loop closures and
    the pose graph; render: the occupancy grid drawn at the optimized poses. Saved beside every
    map it builds (``MAP.build.yaml``) and dumped by ``gatmo config dump mapping``."""

    icp: IcpConfig = Field(default_factory=IcpConfig,
                           description="the scan-matching odometry (ICP against recent scans)")
    graph: GraphConfig = Field(default_factory=GraphConfig,
                               description="keyframes, loop closures and the gtsam pose graph")
    render: RenderConfig = Field(default_factory=RenderConfig,
                                 description="the occupancy grid drawn at the optimized poses")


def load_map_build_config(config_path: str | Path | None = None) -> MapBuildConfig:
    """``config_path``'s map-build configuration (as ``gatmo config dump mapping`` writes, or the
    ``MAP.build.yaml`` an earlier build saved), else the defaults."""
    if config_path is None:
        return MapBuildConfig()
    return load_model(MapBuildConfig, config_path)


def summarize_map_build_config(cfg: MapBuildConfig) -> dict:
    """What ``gatmo info`` says of a map-build configuration: the figures a user tunes first,
    and how many parameters differ from the defaults."""
    g, r = cfg.graph, cfg.render
    return {"kind": "map build config",
            "parameters_not_defaults": _differences(cfg.model_dump(),
                                                    MapBuildConfig().model_dump()),
            "resolution_m": r.resolution_m, "max_range_m": r.max_range_m,
            "keyframe_every": f"{g.keyframe_dist_m:g} m / "
                              f"{math.degrees(g.keyframe_angle_rad):.3g} deg",
            "closure_window_max": f"{g.window_max_m:g} m / "
                                  f"{math.degrees(g.window_theta_max_rad):.3g} deg",
            "closures_agreeing": g.group_size, "icp_max_corr_dist_m": cfg.icp.max_corr_dist_m}


def load_amcl_config(params_path: str | Path | None = None, config_path: str | Path | None = None,
                     preset: str | None = None) -> AmclConfig:
    """The localizer's configuration: the ROS AMCL YAML ``params_path``, else the ``amcl``
    section of the gatmo stack YAML ``config_path`` or of the named stack configuration
    ``preset``, else AMCL's defaults (what ``localize`` and ``calibrate`` take)."""
    if params_path is not None:
        from gatmo.localization.params import load_amcl_yaml

        return load_amcl_yaml(params_path)
    if config_path is not None or preset is not None:
        return load_stack_config(config_path, preset=preset).amcl
    return AmclConfig()


def stack_config_class() -> type[StackConfig]:
    return StackConfig


def load_stack_config(config_path: str | Path | None = None, params_path: str | Path | None = None,
                      preset: str | None = None):
    """Load the stack config.

    ``config_path``: a gatmo stack YAML (sections amcl, gatmo, icp, fusion, seed), as written by
    ``gatmo config dump stack``; or ``preset``, a named one (:data:`STACK_PRESETS`), not both.
    ``params_path``: a ROS 1 / Nav2 AMCL YAML that replaces the ``amcl`` section, so an AMCL
    user's file drops in unchanged.
    """
    if preset is not None:
        if config_path is not None:
            from gatmo.errors import ConfigError

            raise ConfigError("a named configuration or a file, not both (--config)",
                              field="--preset")
        cfg = stack_preset(preset)
    else:
        cfg = load_model(StackConfig, config_path) if config_path is not None else StackConfig()
    if params_path is not None:
        from gatmo.localization.params import load_amcl_yaml

        cfg.amcl = load_amcl_yaml(params_path)
    return cfg


def sim_stack_config(odom=None):
    """The stack config the demo uses on simulated halls: the likelihood_field_prob model with
    sigma_hit 0.1 m (ROS's default likelihood_field weighs so flatly that the filter trails the
    robot by 0.15 m in a furniture hall), ROS 1's
    laser weights (z_hit 0.95, z_rand 0.05) and odometry noise matched to the simulator's
    (Thrun's alphas of ``odom``, a :class:`gatmo.datasets.sim.config.OdomConfig`, by default
    ``SimConfig().odom``'s 0.05 / 0.01 / 0.05 / 0.01; until 2026-11-27 alpha2 and
    alpha4 were 0.05, which let the cloud's heading wander about 3x faster per metre than the
    simulated wheels' and a moved piece in view pull it along: docs/history.md, "The filter's
    odometry noise").
    The initial pose is the simulator's true start, so the initial cloud is 0.1 m / 5 deg
    (std), not AMCL's 0.5 m / 15 deg for a pose clicked in a viewer: with this sharp model the
    first update collapsed a 0.5 m cloud onto a wrong place 0.9-1.9 m off in 8 of 20 runs of
    a rearranged hall, for both sides alike.
    ``amcl.min_explained_beam_fraction`` (off here): measured at 0.5 on 40 hall seeds it
    helps the static localizer (time lost 24.6 % -> 17.9 %) and leaves the full stack where it
    was (5.9 % -> 5.6 %; worse on seeds 200-209, 10.2 % -> 13.0 %); see docs/history.md."""
    cfg = StackConfig()
    a = cfg.amcl
    if odom is None:
        from gatmo.datasets.sim import SimConfig

        odom = SimConfig().odom
    for k, v in dict(laser_model="likelihood_field_prob", sigma_hit_m=0.1,
                     z_hit=0.95, z_rand=0.05, alpha1=odom.alpha1, alpha2=odom.alpha2,
                     alpha3=odom.alpha3, alpha4=odom.alpha4, update_min_d_m=0.1,
                     update_min_a_rad=0.1, min_particles=500,
                     max_particles=3000, initial_cov_xx_m2=0.1**2, initial_cov_yy_m2=0.1**2,
                     initial_cov_aa_rad2=math.radians(5.0)**2).items():
        setattr(a, k, v)
    # a filter confident on a wrong place is started again where the map explains the scan
    # (docs/history.md, "Relocalization"): the demo's run 4 2.47 -> 0.43 m, three of 50 hall
    # seeds better, none worse; the real logs' broad filter is never confident enough for it
    cfg.fusion.relocalize = True
    # a sofa driven past, or two pieces side by side seen in turn, is still though the centre
    # of what is seen wanders (docs/history.md, "Still things that GATMO called persons"): hall
    # seed 416 1.74 -> 0.55 m, five of 50 seeds 7-20 mm worse; the real logs identical
    cfg.gatmo.still_to_gamma = True
    # one scan's returns on a chair reaching past an object's outline rule the object out
    # (a 0.50 m box for a 0.45 m footstool; docs/gatmo.md): false relocations per run 0.275 ->
    # 0.20 on hall seeds 400-419 and 0.325 -> 0.225 on 100-109, 0.263 -> 0.30 on 300-319;
    # over the 50, -0.035 [-0.080, +0.010], finds unchanged. Its threshold is set for the
    # simulator's maps (every cell a piece overlaps occupied)
    cfg.gatmo.match_extent_check = True
    # a piece no return has confirmed in two runs is left out of the localizer's map (and of
    # GATMO's pose test) until seen again: a third of the simulator's pieces move before every
    # run (docs/experiments.md, thirty-ninth session): hall seeds 100-109 ATE 0.132 -> 0.102 m,
    # 400-419 the same; the 50-run soak's time lost over runs 11-50 lower on four chains of
    # five. A run on a fresh map withholds nothing, so the real logs' figures are the same
    cfg.gatmo.withhold_unseen_runs = 2
    # and the returns of a withheld piece that still stands are kept from the localizer, whose
    # map has nothing there to explain them (docs/experiments.md, fortieth session): the
    # soak's time lost over runs 11-50 lower on four chains of five (mean 18.7 -> 16.8 %);
    # the halls and offices the same within 0.005 m
    cfg.fusion.mask_withheld = True
    # a second filter on AMCL's flat model beside the sharp one; the one that strays from the
    # wheels is sent to the other (docs/experiments.md, forty-fourth session): hall seeds
    # 100-109 ATE 0.102 -> 0.095 m (lower on 3, higher on 1), the same before anything moved;
    # 400-419 (where the rule was shaped) 0.117 -> 0.107 m, time lost 1.1 -> 0.7 %
    cfg.fusion.anchor_filter = True
    # and while the two part, the anchor's pose is the one reported if the localizer strayed
    # from the wheels more and the anchor's pose explains the scan nearly as well
    # (docs/experiments.md, forty-seventh session): hall seeds 400-419 ATE 0.107 -> 0.099 m
    # (lower on 13, higher on 5), tuning seeds 300-319 0.174 -> 0.158 m without the fit test;
    # ACES (demo configuration) 0.093 -> 0.078 m, MIT CSAIL the same. GATMO is handed the
    # same poses, so the object map is unchanged
    cfg.fusion.publish_anchor_when_apart = True
    # after the stack itself started the filter again at a pose it tested (the relocalizer,
    # the anchor filter), GATMO's wait ends once the alignment has confirmed three strictly
    # confident poses, not after 3 m of travel during which a piece's old place may pass out
    # of view (docs/experiments.md, fiftieth and fifty-first sessions): over hall seeds 400-419
    # (filter draws 0 and 10) and 100-109, 50 (seed, draw) rows, pieces noticed gone +1.5
    # points [+0.5, +2.6], false relocations +0.06 and twin swaps -0.10 per seed (intervals
    # holding zero), ATE the same; tuning seeds 300-319 ATE 0.164 -> 0.119 m
    cfg.fusion.settle_until_confirmed = True
    # the last confirmed pose carried by the wheels is averaged with the filter's estimate
    # for up to 6 m, not published alone for 0.5 m and then dropped for the filter's
    # (docs/experiments.md, fifty-ninth session): full-stack ATE 0.095 -> 0.091 m (400-419,
    # lower on 20 of 20 seeds), 0.091 -> 0.087 m (100-109, 10 of 10), before anything moved
    # 0.031 -> 0.028 m; real logs (demo configuration, 0.1 m per metre for their wheels)
    # Intel 0.164 -> 0.159 m, ACES 0.084 -> 0.071 m, MIT CSAIL the same. GATMO is handed the
    # same poses
    cfg.fusion.publish_blend = True
    # and while the run's last alignment did not confirm the filter (it contradicted it, did
    # not converge, was degenerate or matched too little), the blend weighs the filter's pose
    # as 0.15 m off, not 0.06 m: its median error there is 0.075-0.15 m against 0.05 m after a
    # confirmation (docs/experiments.md, sixtieth session): full-stack ATE 0.0906 -> 0.0885 m
    # (400-419, lower on 13 of 20 seeds), 0.116 -> 0.115 m (300-319), 100-109 and the offices
    # the same, before anything moved the same; the real logs (demo configuration) the same
    # to the millimetre. GATMO is handed the same poses
    cfg.fusion.publish_blend_suspect_std_m = 0.15
    # and until a run's first tight confirmation, the pose the run was started from, carried by
    # the wheels, stands in for a confirmed one (its deviation the initial cloud's, 0.1 m):
    # 46 % of the tuning halls' squared error came before that confirmation (docs/experiments.md,
    # sixtieth session): ATE 0.115 -> 0.113 m (300-319, lower on 19 of 20 seeds, higher on
    # none), 0.0885 -> 0.0872 m (400-419, lower on 19 of 20), before anything moved the same
    cfg.fusion.publish_blend_from_start = True
    # and the pose published is the one the alignment confirms on the scan the localizer
    # weighs, without the returns GATMO calls unexplained (furniture its map does not have
    # yet, people; the returns of objects missing them by an offset are kept): they loosened
    # the fit, and a loose fit is not published (docs/experiments.md, sixty-first session):
    # ATE 0.087 -> 0.084 m (400-419, lower on 16 of 20 seeds), 0.086 -> 0.080 m (100-109, 10
    # of 10), 0.113 -> 0.111 m (300-319, 14 of 20); before anything moved 0.028 m the same.
    # GATMO is handed the same poses
    cfg.fusion.align_masked = "publish"
    # and that confirmed pose is carried between confirmations by each step's
    # information-weighted average of the wheels' and the scan matcher's ICP step (its
    # covariance 3x), so its error grows 0.035 m per metre, not 0.05: over 1-20 s the carry is
    # off by 15-20 % less than the wheels alone (RMS), the matcher alone being off by 3-5x more
    # (docs/experiments.md, seventieth session): ATE 0.111 -> 0.107 m (300-319, lower on 19 of
    # 20 seeds), 0.0835 -> 0.0815 m (400-419, 16 of 20), 0.080 -> 0.076 m (100-109, 10 of 10),
    # offices 0.0425 -> 0.0419 m (5 of 5), before anything moved 0.0276 -> 0.0270 m and 0.0283
    # -> 0.0281 m. GATMO is handed the same poses
    cfg.fusion.carry_matcher_inflation = 3.0
    cfg.fusion.publish_blend_odom_std_per_m = 0.035
    return cfg


def real_stack_config(sharp_model: bool = True):
    """The stack config the README's real logs were measured with (Intel, ACES, MIT CSAIL;
    ``benchmarks/bench_real_compare.py``): the demo's filter settings (update every 0.1 m /
    0.1 rad, 500-3000 particles) with AMCL's default odometry alphas (0.2) and initial cloud
    (0.5 m / 15 deg). ``sharp_model`` (the benchmark's ``--demo-config``): the demo's
    ``likelihood_field_prob`` with sigma_hit 0.1 m beside an anchor filter on AMCL's flat model.
    The sharp filter alone loses the robot on ACES and MIT CSAIL, whose beams reach 50-80 m (a
    fraction of a degree is a metre there); the anchor keeps it. With it the full stack is
    better than the static localizer on all three logs. Without ``sharp_model``, AMCL's default
    likelihood field (sigma_hit 0.2 m, z_hit 0.5, z_rand 0.5) and no anchor filter: that
    cloud never gets within GATMO's 0.1 m, so the full stack is the static localizer."""
    cfg = sim_stack_config()
    a = cfg.amcl
    a.alpha1 = a.alpha2 = a.alpha3 = a.alpha4 = 0.2
    # AMCL's initial cloud (0.5 m / 15 deg std), not the simulator's: the README's figures
    amcl = type(a)()
    a.initial_cov_xx_m2, a.initial_cov_yy_m2, a.initial_cov_aa_rad2 = (
        amcl.initial_cov_xx_m2, amcl.initial_cov_yy_m2, amcl.initial_cov_aa_rad2)
    if not sharp_model:
        a.laser_model, a.sigma_hit_m, a.z_hit, a.z_rand = "likelihood_field", 0.2, 0.5, 0.5
    # the extent test's threshold is set for the simulator's maps (every cell a piece overlaps
    # occupied); on Intel's map, drawn from the returns, the demo configuration refused with it
    # the two small relocations (8 and 10 cm, half a turn) and moved a third piece 0.38 m
    # instead (docs/experiments.md, thirty-sixth session): off here, as in GatmoConfig
    cfg.gatmo.match_extent_check = False
    # the anchor filter runs AMCL's flat model beside a sharp one: beside the flat default it
    # would be a second draw of the same filter
    cfg.fusion.anchor_filter = sharp_model
    # the pose the alignment confirmed, carried by these wheels (AMCL's alphas, four times the
    # simulator's), is trusted half as long as in the halls: 0.1 m of error per metre, not
    # 0.05 (MIT CSAIL 0.065 -> 0.064 m ATE, Intel and ACES the same or lower; chosen on these
    # three logs from the two values, docs/experiments.md, fifty-ninth session)
    cfg.fusion.publish_blend_odom_std_per_m = 0.1
    # a start pose given with AMCL's 0.5 m cloud is no anchor; not measured on these logs
    cfg.fusion.publish_blend_from_start = False
    # MIT CSAIL's wheels stall (exactly still for a few scans, then the whole motion at once):
    # the published pose follows the scan matcher meanwhile (MIT CSAIL 0.056 -> 0.041 m ATE with
    # the sharp model, 0.124 -> 0.117 m with the flat one; Intel and ACES the same;
    # docs/experiments.md, sixty-ninth session)
    cfg.fusion.publish_through_stalls = True
    # the confirmed pose is carried by the wheels' and the scan matcher's steps together, as in
    # the halls (inherited; its error still grows 0.1 m per metre here): demo configuration,
    # MIT CSAIL 0.039 -> 0.033 m ATE (relations 0.95 -> 0.43 deg), ACES 0.072 -> 0.068 m
    # (0.68 -> 0.43 deg), Intel 0.158 -> 0.157 m (0.046 m / 0.96 deg -> 0.039 m / 0.52 deg);
    # AMCL's flat model the same (it never confirms a pose tightly enough to carry one;
    # docs/experiments.md, seventieth session)
    # ... with the carry's share of the matcher learnt in each run from the confirmations
    # (an unknown robot's wheels and matcher): demo configuration, MIT CSAIL 0.033 -> 0.029 m,
    # ACES 0.068 -> 0.065 m, Intel 0.157 -> 0.155 m (relations 0.039 m / 0.52 deg -> 0.034 m /
    # 0.46 deg), the UoB Stage room's noise-free wheels 0.0723 -> 0.0719 m (static 0.0715);
    # off in the halls, where it changed nothing (docs/experiments.md, seventy-first session)
    cfg.fusion.carry_adapt_inflations = [0.3, 1.0, 3.0, 10.0, 30.0, 100.0]
    return cfg


#: the named stack configurations (``gatmo config dump stack --preset NAME``)
STACK_PRESETS = {
    "amcl": "AMCL's defaults (ROS 1 amcl / Nav2): a broad cloud, so GATMO seldom or never acts",
    "sim": "matched to gatmo's simulator (what `gatmo simulate` writes as stack.yaml)",
    "real": "the real logs' configuration: a sharp sensor model beside an anchor filter on "
            "AMCL's flat model, AMCL's odometry noise and initial cloud",
}


def stack_preset(name: str):
    """The :class:`StackConfig` named ``name`` (a key of :data:`STACK_PRESETS`)."""
    from gatmo.errors import ConfigError

    if name == "amcl":
        return StackConfig()
    if name == "sim":
        return sim_stack_config()
    if name == "real":
        return real_stack_config(sharp_model=True)
    raise ConfigError(f"unknown preset {name!r}: {' | '.join(STACK_PRESETS)}", field="preset")


def summarize_stack_config(cfg) -> dict:
    """What ``gatmo info`` says of a stack configuration: the localizer's sensor and motion
    models, whether GATMO can act (its strict test), the named preset it is, if any, and how
    many parameters differ from AMCL's defaults (:class:`StackConfig`)."""
    a, f = cfg.amcl, cfg.fusion
    same = [name for name in STACK_PRESETS if stack_preset(name) == cfg]
    return {"kind": "stack config", "preset": same[0] if same else "none",
            "parameters_not_amcl_defaults": _differences(cfg.model_dump(),
                                                         StackConfig().model_dump()),
            "laser_model": a.laser_model, "sigma_hit_m": a.sigma_hit_m,
            "alphas": [a.alpha1, a.alpha2, a.alpha3, a.alpha4],
            "initial_std_xy_m": round(math.sqrt(a.initial_cov_xx_m2), 4),
            "anchor_filter": f.anchor_filter,
            "gatmo_needs_cloud_within": f"{f.absence_max_std_xy_m:g} m / "
                                        f"{f.absence_max_std_theta_deg:g} deg",
            "seed": cfg.seed}


def _differences(a, b) -> int:
    if isinstance(a, dict) and isinstance(b, dict):
        return sum(_differences(a.get(k), b.get(k)) for k in set(a) | set(b))
    return int(a != b)


def dump_stack_config(cfg) -> str:
    return dump_model(cfg)


__all__ = ["STACK_PRESETS", "MapBuildConfig", "StackConfig", "dump_stack_config",
           "load_amcl_config", "load_map_build_config", "load_stack_config",
           "real_stack_config", "sim_stack_config", "stack_config_class", "stack_preset",
           "summarize_map_build_config", "summarize_stack_config"]
