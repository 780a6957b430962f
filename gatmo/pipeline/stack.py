"""The full stack of the GATMO paper (Fig. 3): localizer + scan matcher + object map.

Per scan:

1. the Monte Carlo localizer takes odometry and the scan and gives the global pose with its
   particle covariance;
2. the scan matcher registers the scan in its own frame (``T_match_base``); gatmo keeps the offset
   ``T_map_match`` between the matcher's frame and the map and resets it to the localizer's estimate
   whenever the particle covariance says the filter is confident (paper, Sec. IV-B: "We use the
   covariance of the AMCL's particle filter as an indicator of when to reset the scan matching
   offset"); the output pose is ``T_map_match * T_match_base``;
3. GATMO lays the scan onto the object map from that precise pose (absence only while confident);
4. the cells GATMO changed go back into the localizer's likelihood field (region updates only), so
   moved furniture helps localization instead of hurting it.

Only numpy and gatmo's algorithm types are used here; files are the business of
:mod:`gatmo.pipeline.runs`.
"""

from __future__ import annotations

import inspect
import time
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar, Literal

import numpy as np
from pydantic import Field, PositiveFloat

from gatmo.config import GatmoModel
from gatmo.datasets.types import Scan
from gatmo.geometry import compose, inverse, relative, transform_points, wrap_angle
from gatmo.maps.grid import OccupancyGrid


class FusionConfig(GatmoModel):
    """When the scan matcher's offset is reset to the localizer's estimate.

    The localizer is *confident* when it ran a sensor update on this scan, its heaviest cluster
    has position standard deviations below ``reset_max_std_xy_m`` and heading standard deviation
    below ``reset_max_std_theta_deg``: the matcher's offset is then reset. GATMO lays scans onto
    the object map only under the stricter ``absence_max_std_*`` (or within ``confident_for_m``
    of travel after a reset): a wrong pose sees through everything. When the localizer's pose
    jumps against odometry by more than ``max_offset_jump_m`` (recovery injected particles, a
    kidnapping), or AMCL's recovery injects random particles at all (it suspects it is lost; the
    cloud may then drift to a look-alike place without a jump), GATMO waits
    ``settle_after_jump_m`` of travel: a filter that has just locked onto a look-alike place is
    as confident as one that is right.

    ``align_to_map``: GATMO's pose is the published one refined by ICP against the current map.
    An alignment that converges with most points matched but moves the pose by more than
    ``align_max_correction_*`` contradicts the filter: GATMO skips the scan. One that is
    inconclusive (not converged, degenerate, or fewer than ``align_min_fitness`` of the points
    matched) says nothing either way in a rearranged room, where the moved furniture is what
    does not match: ``align_inconclusive: filter_pose`` hands GATMO the filter's pose (its own
    beam-agreement tests still apply), ``skip`` skips the scan (GATMO then saw 20 of 600 scans
    of a simulated rearranged hall). GATMO is told which poses the alignment confirmed
    (``pose_verified``): new objects need scans from such poses
    (``gatmo.gamma_min_verified_scans``).
    The alignment runs at most ``align_max_iter`` Gauss-Newton steps with ``align_kernel``
    weights at ``align_kernel_scale_m``: ``geman_mcclure`` (redescending, as kiss-icp) lets
    furniture moved by less than the 0.3 m correspondence gate drop out instead of pulling the
    pose towards where it stood.

    ``mask_unexplained``: returns that land, seen from the pose odometry predicts, where GATMO
    found this run's returns unexplained by the current map (furniture it has not placed yet,
    people) are withheld from the localizer. Beyond the paper.
    ``mask_withheld`` (off; on in ``sim_stack_config``; needs ``mask_unexplained``) also
    withholds returns within delta_W of an object left out of the localizer's map
    (``gatmo.withhold_unseen_runs``): where such a piece still stands, its returns would land
    far from anything in the localizer's map and pull the filter to wherever they fall near
    something; where it has gone, beams pass its place and nothing is withheld.
    ``mask_offset_objects`` (on; needs ``mask_unexplained``) withholds, scan by scan, the
    returns of an object that all miss it by a consistent offset while the rest of the scan
    fits the map (:meth:`gatmo.objects.mapper.GatmoMapper.offset_at`, placed from the pose
    odometry predicts), while the filter's last estimate passes GATMO's strict confidence test
    (``absence_max_std_*``; a broad cloud's prediction is no base for a 5 cm fit): a piece
    shifted by a decimetre or more, before GATMO has relocated it, pulls a likelihood field
    towards its old place. Measured against it off (``bench_gatmo_sim``, tuning hall seeds
    300-319, 2026-11-25): full-stack ATE lower on 17 of 20 seeds, false relocations 1.65 ->
    1.25 per seed, time lost unchanged (7.8 % -> 7.7 %); without the confidence gate time lost
    fell to 6.0 %, but on the Intel log the full stack was then worse than the static
    localizer (0.199 against 0.196 m ATE). See docs/experiments.md.

    ``publish_pose``: the pose the stack reports. ``aligned`` (default; needs GATMO and
    ``align_to_map``): the pose the scan-to-map alignment confirmed on the last scan it confirmed
    with at least ``publish_min_tight_fraction`` of its points within ``align_tight_m`` of a map
    edge (a confirmed but loose fit can be a wrong local one: the demo's run 2 starts 0.33 m off and
    such a fit 0.42 m off), carried by the wheels' odometry for at most ``publish_carry_m`` /
    ``publish_carry_deg``, else the filter's own estimate (also when the carried pose strays more
    than ``max_offset_jump_m`` from it, or the filter jumped). With ``publish_blend`` the carried
    pose is averaged with the filter's estimate, each weighed by the inverse of its variance (the
    carried pose's grows with the distance it has moved from where it was confirmed), up to
    ``publish_blend_max_m`` away: past 0.5 m the filter alone is off by 0.11 m RMS on the rearranged
    halls, most of their ATE (docs/experiments.md, fifty-ninth session). While the run's last
    alignment did not confirm the filter, the filter weighs ``publish_blend_suspect_std_m``
    instead of ``publish_blend_filter_std_m`` (sixtieth session). The particle mean trails a
    sharp likelihood field by a few cm; the alignment puts a scan onto the map's edges. Against
    ``localizer`` (twenty-fourth session): simulated halls before anything moved 0.060 -> 0.032 m
    ATE (seeds 100-109), rearranged 0.150 -> 0.144 m (300-319, lower on 18 of 20), 0.153 -> 0.148 m
    (100-109) and 0.301 -> 0.295 m (400-419), offices 0.053 -> 0.043 m (lower on 5 of 5), Intel
    (demo configuration) 0.183 -> 0.177 m, median 0.102 -> 0.080 m, relations 0.060 -> 0.053 m;
    GATMO's work is unchanged (it is handed the same poses). With a filter never strictly confident
    (AMCL's broad default field on the real logs) it is the filter's pose. ``localizer``: the
    filter's own estimate, carried by odometry between its updates, as AMCL publishes it. ``fused``:
    the matcher's pose re-anchored on the filter (paper, Sec. IV-B), locally more precise (Intel
    relations 0.052 m / 0.65 deg against 0.061 m / 0.94 deg) but with larger errors between resets
    (ATE 7-11 % higher in simulated offices where nothing moved).

    ``relocalize`` (off by default; on in the simulated halls' configuration,
    ``gatmo.pipeline.config.sim_stack_config``, since the twenty-fifth session; needs GATMO's
    map and a localizer with ``set_initial_pose``; beyond AMCL, in the spirit of slam_toolbox's
    localization mode; docs/history.md, "Relocalization"): a filter can be confident and wrong,
    its cloud too tight to reach the right place again (AMCL's random particles lock onto look-alike
    places of a sparse hall). When a confident filter's pose (the reset test,
    ``reset_max_std_*``; a broad cloud still reaches the right place by itself) after an update
    explains at most ``relocalize_below_fit`` of the scan's points (within ``relocalize_fit_m``
    of a map edge; at least ``relocalize_min_points`` points), a correlative search of the
    current map in +- ``relocalize_window_m`` / ``relocalize_window_deg`` around it, refined by
    ICP (:func:`gatmo.scanmatch.correlative.match_to_submap`: high peak, no other place 0.3 m
    away scoring ``relocalize_ambiguity_ratio`` of it, ICP agrees), looks for a pose explaining
    at least ``relocalize_min_fit`` of them, and ``relocalize_min_gain`` more than the filter's
    pose does. Found on ``relocalize_scans`` updates in a row that agree after odometry (0.2 m /
    5 deg), and at least ``relocalize_min_shift_m`` from the filter but no farther than
    ``relocalize_max_jump_m`` plus ``relocalize_max_jump_per_m`` times the travel since the
    filter last explained ``relocalize_min_fit`` of a scan (or since the run's start: a run's
    given initial pose is trusted, and pieces moved before the run fit the scan at wrong places
    near it), the filter is started again there (``relocalize_std_xy_m`` /
    ``relocalize_std_deg``) and GATMO waits as after any jump (``settle_after_jump_m``).
    Only a pose from which the current map, ray-cast, expects at least
    ``relocalize_min_expected_beams`` beams to end on something within the laser's range is
    searched around (:meth:`LocalizationStack._expects_enough`; beyond slam_toolbox). A
    rearranged room's returns come mostly from things the map has elsewhere or not at all;
    where the map expects to see (almost) nothing, explaining little of the scan is no sign of
    a wrong pose, and a search there lays those returns onto whatever the map has within the
    window (hall seed 410 run 2: a filter 0.2 m off with 0-8 beams expected to end, restarted
    1 m off on a desk's and a lounge chair's returns laid onto two columns). The restarts
    that mend a lost filter came with 53-86 such beams (demo run 4, hall seeds 305 runs 2 and
    3, 318 run 4). At 10 (thirty-eighth session) hall seed 410 went 0.50 -> 0.08 m ATE, and
    every other seed of 400-419, 100-109 and 300-319 stayed the same to the digit.

    ``anchor_filter`` (off by default; beyond AMCL): a second filter with AMCL's flat
    ``likelihood_field`` model runs beside the localizer on the same map and the raw scans. The
    sharp model GATMO needs slides onto a moved piece that fits its returns (hall seed 403
    run 3: 0.45 m in 3 s); the flat one, each beam's say bounded, seldom does. When they part
    (``anchor_gap_m`` on ``anchor_gap_updates`` updates in a row), the one that moved against
    odometry since they last agreed is started again at the other's pose, the localizer only
    if the anchor's pose explains the scan nearly as well as its own (a filter correcting itself
    strays from the wheels too). Where the localizer is right, the two part by at most
    0.17-0.22 m (hall seeds 403, 412, 416); where the anchor is lost instead (seed 417 run 1,
    0.9 m off), the wheels say so (docs/experiments.md, forty-fourth session). "Since they
    last agreed" counts from where both were started (a run's initial pose, a restart).
    ``publish_anchor_when_apart`` reports the anchor's pose while the two are more than
    ``anchor_agree_m`` apart and the same tests point at the localizer, before (or without) a
    restart: hall seeds 400-419 ATE 0.107 -> 0.099 m; GATMO's poses are untouched
    (docs/experiments.md, forty-seventh session).

    ``passes`` (1; offline, beyond the paper and AMCL): a log is run again, its localizer,
    alignment and relocalizer on the map the pass before ended with, fixed (the pieces that
    pass found moved, gone or new already where it left them), and its GATMO starting again
    from the object map the run began with (:func:`gatmo.pipeline.runs.run_full`).
    ``passes_objects: first`` keeps the first pass's object map and the last pass's poses;
    ``last`` keeps both from the last pass. Hall seeds 400-419 and 100-109, two passes, ``first``:
    the object map is the one-pass map, the full stack's ATE 0.191 -> 0.161 m and 0.149 ->
    0.109 m (lower on 15 of 20 and 6 of 10 seeds), time lost 2.9 -> 2.0 % and 1.8 -> 0.6 %;
    ``last``: GATMO, better localized, finds about as many pieces and makes 0.45-0.6 more
    false relocations per seed (docs/experiments.md, thirty-fifth session). Each pass costs a
    pass's time. Off: a robot localizing live has one pass.
    """

    # built, measured as no better than the defaults and left off, then removed (forty-second
    # session and later, docs/experiments.md); a file naming one at its old default still loads
    removed_options: ClassVar[dict[str, Any]] = {
        "settle_after_start_m": 0.0, "slide_check": False, "slide_window_m": 2.0,
        "slide_max_m": 0.4, "align_min_tight_fraction": 0.0, "align_chain_check": False,
        "align_chain_tol_m": 0.04, "align_chain_tol_per_m": 0.05, "align_chain_tol_deg": 2.0,
        "align_chain_tol_deg_per_m": 1.0, "align_chain_stale_m": 2.0,
        "align_chain_switch_scans": 5, "verified_suffices": False, "verified_track": True,
        "mask_doubted": False, "mask_offset_beams": False, "mask_offset_beams_reset_test_m": 3.0,
        "coast_withheld_fraction": 0.0, "coast_max_m": 3.0, "gatmo_pose_gain": 1.0,
        "gatmo_pose_carry_m": 0.0, "motion_from_matcher": False,
        "matcher_motion_max_gap_m": 0.2, "matcher_motion_max_gap_deg": 10.0,
        "bridge_evidence": False, "bridge_max_closure_m": 0.02, "bridge_max_closure_deg": 1.0,
        "bridge_max_travel_m": 3.0,
        # (sixtieth and sixty-first sessions)
        "tight_between_updates": "off", "publish_tight_contradictions": False,
        "restart_tight_contradictions": 0, "restart_agree_m": 0.05, "restart_agree_deg": 2.0,
        # (sixty-second session; with align_masked's values rescue and both, code at c9a711a)
        "align_masked_fallback": False}

    use_scan_matcher: bool = Field(
        True, description="run the ICP scan matcher beside the localizer; its frame is reset "
        "onto the filter's estimate when the filter is confident. Off: the fused pose is the "
        "localizer's own")
    publish_through_stalls: bool = Field(
        False, description="while the wheels report exactly no motion between scans (a stall, "
        "or the robot standing) and the scan matcher's ICP fits say it moved, the published "
        "pose moves by the matcher's steps since the wheels stopped; the filter and GATMO are "
        "untouched (the filter updates on the wheels' travel and stands still through a "
        "stall). Needs use_scan_matcher")
    carry_matcher_inflation: float | None = Field(
        None, gt=0, description="with publish_pose aligned: the last tightly confirmed pose is "
        "carried not by the wheels alone but by each step's information-weighted average of "
        "the wheels' step and the scan matcher's ICP step, the ICP covariance multiplied by "
        "this (its fits on people and along straights are confidently off), the wheels' "
        "step deviation carry_wheel_std_per_m per metre and carry_wheel_std_per_rad per "
        "radian. None: the wheels alone. Needs use_scan_matcher")
    carry_adapt_inflations: list[PositiveFloat] | None = Field(
        None, min_length=2, description="with carry_matcher_inflation: the carry is run with "
        "each of these inflations side by side; at tight confirmations carry_adapt_spacing_m "
        "of travel apart, each carry's pose carried from each earlier one within "
        "carry_adapt_max_m is scored against it (squared error, heading at 1 m/rad, "
        "forgotten over carry_adapt_halflife_m of travel), and the carry published is the "
        "one scoring best once carry_adapt_min_pairs were scored (carry_matcher_inflation "
        "until then). Learns, in each run, how far this robot's wheels and scan matcher are "
        "to be trusted. None: carry_matcher_inflation always")
    carry_adapt_spacing_m: float = Field(
        0.3, gt=0, description="see carry_adapt_inflations: the least travel between two "
        "confirmations scored against each other, and between two kept to score from (a "
        "shorter stretch measures the confirmations' own noise) [m]")
    carry_adapt_max_m: float = Field(
        6.0, gt=0, description="see carry_adapt_inflations: the most travel between two "
        "confirmations scored against each other (publish_blend_max_m: no carry is published "
        "farther) [m]")
    carry_adapt_halflife_m: float = Field(
        30.0, gt=0, description="see carry_adapt_inflations: travel after which a scored "
        "pair counts half [m]")
    carry_adapt_min_pairs: int = Field(
        20, ge=1, description="see carry_adapt_inflations: pairs of confirmations scored "
        "before the choice leaves carry_matcher_inflation")
    carry_wheel_std_per_m: float = Field(
        0.07, gt=0, description="see carry_matcher_inflation: the wheels' step deviation in "
        "translation per metre of the step [m/m] (and 0.15 of it in heading [rad/m]), on top of "
        "2 mm / 2 mrad")
    carry_wheel_std_per_rad: float = Field(
        0.05, gt=0, description="see carry_matcher_inflation: the wheels' step deviation in "
        "heading per radian turned [rad/rad] (and 0.2 of it in translation [m/rad])")
    publish_pose: Literal["localizer", "fused", "aligned"] = Field(
        "aligned", description="the pose the stack reports: aligned, the last pose the "
        "scan-to-map alignment confirmed with a tight fit, carried by odometry (needs GATMO and "
        "align_to_map, else the filter's estimate); localizer, the filter's own estimate; fused, "
        "the matcher's pose re-anchored on the filter")
    publish_carry_m: float = Field(
        0.5, ge=0, description="with publish_pose aligned: the last tightly confirmed pose is "
        "carried by odometry while it has moved at most this far from where it was "
        "confirmed; beyond, the filter's estimate is published")
    publish_carry_deg: float = Field(
        20.0, ge=0, description="with publish_pose aligned: the last tightly confirmed pose is "
        "carried by odometry while its heading has turned at most this much since it was "
        "confirmed; beyond, the filter's estimate is published")
    publish_blend: bool = Field(
        False, description="with publish_pose aligned: the last tightly confirmed pose carried "
        "by odometry is not published as it is but averaged with the filter's estimate, each "
        "weighed by the inverse of its variance: the carried pose's standard deviation is "
        "publish_blend_base_std_m plus publish_blend_odom_std_per_m per metre it has moved "
        "(by the wheels, in a straight line) from where it was confirmed, the filter's "
        "publish_blend_filter_std_m; it is carried while it has moved at most "
        "publish_blend_max_m (publish_carry_m / _deg do not apply)")
    publish_blend_base_std_m: float = Field(
        0.02, gt=0, description="see publish_blend: the confirmed pose's own error [m]")
    publish_blend_odom_std_per_m: float = Field(
        0.05, ge=0, description="see publish_blend: the carried pose's error grown per metre it "
        "has moved from where it was confirmed [m/m]")
    publish_blend_filter_std_m: float = Field(
        0.06, gt=0, description="see publish_blend: the filter's error where the alignment did "
        "not confirm a pose [m] (its particle spread says less: near moved furniture it is "
        "confident and off)")
    publish_blend_suspect_std_m: float = Field(
        0.06, gt=0, description="see publish_blend: the filter's error [m] while the last "
        "scan-to-map alignment (on the run's latest trusted scan) did not confirm its pose "
        "(contradicts, not_converged, degenerate, low_fitness); publish_blend_filter_std_m "
        "after a confirmation")
    publish_blend_from_start: bool = Field(
        False, description="see publish_blend: until a run's first tight confirmation, the pose "
        "the run was started from (a given initial pose), carried by the wheels, is averaged "
        "with the filter's as a confirmed one is, its own error the initial cloud's standard "
        "deviation instead of publish_blend_base_std_m")
    publish_blend_max_m: float = Field(
        6.0, ge=0, description="see publish_blend: once the carried pose has moved farther than "
        "this from where it was confirmed, the filter's estimate is published")
    publish_min_tight_fraction: float = Field(
        0.8, ge=0, le=1, description="with publish_pose aligned: a pose the alignment confirmed "
        "is published only if at least this fraction of its points lie within align_tight_m of "
        "a map edge (a loose fit can be a wrong local one)")
    reset_max_std_xy_m: float = Field(
        0.15, description="the localizer is confident (its estimate resets the matcher's frame; "
        "relocalize checks its pose) when, on a scan it weighed, its position standard "
        "deviation is at most this and its heading's at most reset_max_std_theta_deg")
    reset_max_std_theta_deg: float = Field(
        5.0, description="the confidence test's bound on the localizer's heading standard "
        "deviation (see reset_max_std_xy_m)")
    absence_max_std_xy_m: float = Field(
        0.1, description="GATMO's stricter test: a pose is handed to GATMO as trusted only "
        "while the localizer's position standard deviation is at most this and its heading's "
        "at most absence_max_std_theta_deg (or within confident_for_m of a reset)")
    absence_max_std_theta_deg: float = Field(
        3.0, description="the bound of GATMO's stricter test on the localizer's heading "
        "standard deviation (see absence_max_std_xy_m)")
    confident_for_m: float = Field(
        0.0, description="travel of the stack's pose since the localizer last passed the reset "
        "test (reset_max_std_*) within which GATMO is still handed that pose as trusted, though "
        "the filter fails the stricter absence_max_std_* test")
    max_offset_jump_m: float = Field(
        0.5, description="a localizer pose that jumps against odometry by more than this makes "
        "GATMO wait settle_after_jump_m. A fused pose farther than this from the localizer's "
        "means the matcher diverged (its frame is reset onto the filter's estimate), and a "
        "carried aligned pose this far off gives way to the filter's estimate")
    offset_gain: float = Field(
        1.0, description="the fraction of the way a confident reset moves the matcher's frame "
        "onto the filter's estimate: 1 resets it fully (the paper), less averages the filter's "
        "jitter out. A run's first anchoring is always full")
    max_travel_without_reset_m: float = Field(
        1.0, description="travel of the fused pose since the localizer was last confident "
        "beyond which the matcher's offset counts as stale: the localizer's pose is used and "
        "the matcher's frame re-anchored on it every scan")
    settle_after_jump_m: float = Field(
        3.0, description="odometry travel GATMO waits, handed no trusted pose, after the "
        "localizer's pose jumped (max_offset_jump_m), its recovery injected random particles, "
        "or the stack started it again (relocalize, anchor_filter)")
    settle_until_confirmed: bool = Field(
        False, description="after the stack started the filter again at a pose it tested "
        "(relocalize, anchor_filter), GATMO's wait (settle_after_jump_m) ends early once the "
        "scan-to-map alignment has confirmed settle_confirmed_poses of the filter's strictly "
        "confident poses since; a jump of the filter itself keeps the full wait. Off here, on "
        "in sim_stack_config (docs/experiments.md, fiftieth and fifty-first sessions)")
    settle_confirmed_poses: int = Field(3, ge=1, description="see settle_until_confirmed")
    align_masked: Literal["off", "publish", "all"] = Field(
        "off", description="the scan-to-map alignment on the scan the localizer weighs, "
        "without the returns mask_unexplained withholds (furniture the map does not have yet, "
        "people, withheld objects; an object's returns missing it by a consistent offset are "
        "kept: with a right map they show the pose off): publish, a second "
        "alignment of that scan (where returns were withheld) gives the pose published "
        "(publish_pose aligned) while GATMO's poses and their checks stay the full scan's; "
        "all, the one alignment is of that scan, for both. GATMO is handed every return")
    align_to_map: bool = Field(
        True, description="refine the pose handed to GATMO by ICP of the scan against the "
        "current map's edges (MapAligner): a confirmed pose goes to GATMO as verified, one the "
        "alignment contradicts skips the scan. Needed by publish_pose aligned")
    align_min_fitness: float = Field(
        0.6, description="the alignment is inconclusive (align_inconclusive) when fewer than "
        "this fraction of the scan's points are matched to a map edge within the 0.3 m "
        "correspondence gate")
    align_max_correction_m: float = Field(
        0.15, description="a conclusive alignment that moves the pose by more than this "
        "contradicts the filter: GATMO skips the scan")
    align_max_correction_deg: float = Field(
        5.0, description="a conclusive alignment that turns the pose by more than this "
        "contradicts the filter: GATMO skips the scan")
    align_inconclusive: Literal["filter_pose", "skip"] = Field(
        "filter_pose", description="an inconclusive alignment (not converged, degenerate, fewer "
        "than align_min_fitness of the points matched, too few points, no map): filter_pose "
        "hands GATMO the unrefined pose as trusted but not verified, skip skips the scan")
    align_kernel: Literal["huber", "geman_mcclure"] = Field(
        "huber", description="robust kernel weighting the alignment's residuals: huber, or "
        "geman_mcclure (redescending, as kiss-icp), which lets furniture moved by less than the "
        "0.3 m correspondence gate drop out instead of pulling the pose")
    align_kernel_scale_m: float = Field(
        0.05, gt=0, description="align_kernel's scale: huber lets a residual beyond it pull "
        "with a constant force, geman_mcclure one several times it almost not at all")
    align_max_iter: int = Field(
        15, ge=1, description="most Gauss-Newton steps of the alignment; one not converged "
        "within them is inconclusive")
    align_tight_m: float = Field(
        0.05, gt=0, description="a point of a confirmed alignment is tight within this of a "
        "map edge at the pose it converged to (publish_min_tight_fraction)")
    mask_unexplained: bool = Field(
        True, description="withhold from the localizer the returns that land, placed from the "
        "pose odometry predicts, where GATMO found this run's returns unexplained by the "
        "current map (furniture it has not placed yet, people). Needs GATMO")
    mask_withheld: bool = Field(
        False, description="with mask_unexplained: also withhold the returns within delta_W of "
        "an object left out of the localizer's map (gatmo.withhold_unseen_runs), which that "
        "map has nothing to explain where the object still stands")
    mask_offset_objects: bool = Field(
        True, description="with mask_unexplained: also withhold, scan by scan, the returns of an "
        "object that all miss it by a consistent offset while the rest of the scan fits the "
        "map (GatmoMapper.offset_at), while the filter's last estimate passes the "
        "absence_max_std_* test")
    relocalize: bool = Field(
        False, description="start a confident localizer whose pose explains too little of the "
        "scan again where a correlative search of the current map, refined by ICP, finds a "
        "pose explaining more. Needs GATMO's map and a localizer with set_initial_pose")
    relocalize_below_fit: float = Field(
        0.3, ge=0, le=1, description="search only when the filter's pose explains at most this "
        "fraction of the scan's points (within relocalize_fit_m of a map edge)")
    relocalize_min_fit: float = Field(
        0.5, ge=0, le=1, description="a found pose must explain at least this fraction of the "
        "scan's points; the filter's pose explaining this much restarts the travel counted for "
        "relocalize_max_jump_per_m")
    relocalize_min_gain: float = Field(
        0.25, ge=0, le=1, description="a found pose must also explain at least this fraction "
        "of the scan's points more than the filter's pose does")
    relocalize_ambiguity_ratio: float = Field(
        0.9, gt=0, le=1, description="the search finds nothing when a second peak more than "
        "0.3 m from the best scores at least this fraction of it")
    relocalize_fit_m: float = Field(
        0.1, gt=0, description="a scan point is explained within this of a map edge; also the "
        "sigma of the search's likelihood field")
    relocalize_window_m: float = Field(
        1.5, gt=0, description="the search's half-width in x and y around the filter's pose; "
        "a pose found within 0.1 m of the window's edge is refused")
    relocalize_window_deg: float = Field(
        15.0, gt=0, description="the search's half-width in heading around the filter's pose; "
        "a pose found within 1 deg of the window's edge is refused")
    relocalize_scans: int = Field(
        3, ge=1, description="the filter is started again only once a pose was found on this "
        "many checks in a row (its confident updates), agreeing after odometry (0.2 m, 5 deg)")
    relocalize_min_points: int = Field(
        30, ge=3, description="fewest scan points (5 cm voxels) for the fit test and the search "
        "to run")
    relocalize_min_shift_m: float = Field(
        0.2, ge=0, description="a found pose closer than this to the filter's is not taken")
    relocalize_max_jump_m: float = Field(
        0.3, ge=0, description="a found pose farther from the filter's than this plus "
        "relocalize_max_jump_per_m times the odometry travel since the filter last explained "
        "relocalize_min_fit of a scan (or since the run's start) is not taken")
    relocalize_max_jump_per_m: float = Field(
        1.0, ge=0, description="metres the farthest restart grows by per metre of odometry "
        "travel since the filter last fitted the map (see relocalize_max_jump_m)")
    relocalize_min_expected_beams: int = Field(
        10, ge=0, description="search only around a pose from which the current map, ray-cast, "
        "expects at least this many beams to end on something within the laser's range (0: "
        "wherever the pose explains too little of the scan)")
    relocalize_std_xy_m: float = Field(
        0.05, gt=0, description="position standard deviation of the particles a filter is "
        "started again with by the stack (relocalize, anchor_filter)")
    relocalize_std_deg: float = Field(
        2.0, gt=0, description="heading standard deviation of the particles a filter is "
        "started again with by the stack (relocalize, anchor_filter)")
    anchor_filter: bool = Field(
        False, description="run a second particle filter beside the localizer, on the same map "
        "and the raw scans, with AMCL's flat sensor model (anchor_laser_model, "
        "anchor_sigma_hit_m; the rest of the localizer's parameters alike). When the two part "
        "by more than anchor_gap_m on anchor_gap_updates of the localizer's updates in a row, "
        "the one that moved against odometry since they last agreed (within anchor_agree_m) "
        "is started again at the other's pose (relocalize_std_*): the localizer if it strayed "
        "more than the anchor by anchor_odom_margin_m and the anchor's pose explains the scan "
        "nearly as well (at most anchor_fit_margin less of it within relocalize_fit_m of the "
        "map), and then GATMO waits settle_after_jump_m; the anchor if it strayed more. The "
        "sharp model's cloud can slide onto moved furniture; the flat one gives each beam a "
        "bounded say, and where it is lost instead, the wheels tell which of the two moved")
    anchor_laser_model: Literal["likelihood_field", "likelihood_field_prob", "beam"] = Field(
        "likelihood_field", description="the anchor filter's sensor model (AMCL's default)")
    anchor_sigma_hit_m: float = Field(0.2, gt=0, description="the anchor filter's sigma_hit "
                                      "(AMCL's default)")
    anchor_gap_m: float = Field(0.3, gt=0, description="see anchor_filter")
    anchor_agree_m: float = Field(0.2, gt=0, description="see anchor_filter")
    anchor_odom_margin_m: float = Field(0.1, ge=0, description="see anchor_filter")
    anchor_fit_margin: float = Field(0.1, ge=0, le=1, description="see anchor_filter")
    anchor_gap_updates: int = Field(5, ge=1, description="see anchor_filter")
    publish_anchor_when_apart: bool = Field(
        False, description="with anchor_filter: while the localizer and the anchor are more "
        "than anchor_agree_m apart and the localizer has moved against odometry more than the "
        "anchor since they last agreed and the anchor's pose explains the scan nearly as well "
        "(anchor_fit_margin), the stack reports the anchor's pose (the localizer "
        "is not started again until anchor_gap_updates say so; GATMO still gets only the "
        "localizer's trusted poses)")
    anchor_gates_gatmo: bool = Field(
        False, description="with anchor_filter: GATMO is handed no scan on which the localizer "
        "and the anchor filter are more than anchor_gate_gap_m apart. Two filters that far "
        "apart put the pose in doubt, and on a straight with little but moved furniture in "
        "view the scan-to-map alignment can confirm a pose 0.9 m off. Measured and left off "
        "(docs/experiments.md, forty-fifth and fiftieth sessions): it rescues some runs and "
        "loses others")
    anchor_gate_gap_m: float = Field(
        0.3, gt=0, description="see anchor_gates_gatmo (0.15 m in the forty-fifth session, "
        "where it also kept from GATMO the scans that noticed pieces gone)")
    passes: int = Field(
        1, ge=1, le=4, description="passes over each log (offline): every pass after the "
        "first localizes on the map the pass before ended with, fixed, and GATMO starts again "
        "from the object map the run began with; the last pass's poses and object map are kept")
    passes_objects: Literal["first", "last"] = Field(
        "first", description="with passes > 1: the object map of the first pass, or of the "
        "last (the poses are always the last pass's)")


#: what a scan-to-map alignment (:meth:`MapAligner.refine`) concluded: ``confirmed`` the pose;
#: ``contradicts`` it (converged, matched, but corrects it more than ``align_max_correction_*``);
#: inconclusive: ``not_converged`` (within ``align_max_iter``), ``degenerate``, ``low_fitness``
#: (below ``align_min_fitness``), ``few_points`` (under 20 after downsampling) or ``no_map``
ALIGN_OUTCOMES = ("confirmed", "contradicts", "not_converged", "degenerate", "low_fitness",
                  "few_points", "no_map")
#: the alignment outcomes after which the published blend trusts the filter less
#: (publish_blend_suspect_std_m): the filter's median error after each is 0.075-0.15 m on the
#: rearranged halls, 0.05 m after a confirmation (docs/experiments.md, sixtieth session)
SUSPECT_OUTCOMES = ("contradicts", "not_converged", "degenerate", "low_fitness")


def _edge_points(grid: OccupancyGrid) -> np.ndarray:
    """Map-frame centres (M, 2) [m] of the occupied cells with a free or unknown neighbour."""
    from scipy import ndimage

    occ = grid.occupied
    iy, ix = np.nonzero(occ & ~ndimage.binary_erosion(occ, border_value=0))
    return grid.cell_to_world(np.stack([ix, iy], axis=1))


@dataclass
class MapAligner:
    """Scan-to-map ICP around a pose: the precise pose GATMO needs, and a check of it.

    The localizer's covariance says how tight its particles are, not whether they are right;
    a filter that locked onto the wrong place is confident too. Aligning the scan with the
    current map's edges (converged, small correction, most points matched) is a direct test.
    """

    def __init__(self, fusion: FusionConfig):
        self.fusion = fusion
        self._grid_id = None
        self._tree = None
        self._pts = None
        self._normals = None
        self.last_verified = False  # the last refine() confirmed the pose (not inconclusive)
        #: why the last refine() confirmed the pose or not: one of ALIGN_OUTCOMES
        self.last_outcome = "no_map"
        #: of the last refine()'s points, the fraction within ``align_tight_m`` of a map edge
        #: at the pose it converged to (0 when it did not run)
        self.last_tight_fraction = 0.0

    def set_grid(self, grid: OccupancyGrid, edges_xy: np.ndarray | None = None) -> None:
        """Align against ``grid``'s edges: ``edges_xy`` (M, 2), its :func:`_edge_points`
        if already worked out."""
        from scipy.spatial import cKDTree

        from gatmo.scanmatch.icp import normals_of

        self._pts = _edge_points(grid) if edges_xy is None else edges_xy
        self._tree = cKDTree(self._pts) if len(self._pts) >= 10 else None
        if self._tree is not None:
            self._normals, _ = normals_of(self._pts, self._tree)

    def refine(self, pose_xytheta: np.ndarray, scan: Scan) -> tuple[np.ndarray, bool]:
        """(refined base pose, trustworthy) for a scan near ``pose_xytheta``; an inconclusive
        alignment gives the pose back, trusted only with ``align_inconclusive: filter_pose``."""
        from gatmo.scanmatch.icp import icp_2d, voxel_downsample

        f = self.fusion
        inconclusive = (pose_xytheta, f.align_inconclusive == "filter_pose")
        self.last_verified = False
        self.last_outcome = "no_map"
        self.last_tight_fraction = 0.0
        if self._tree is None:
            return inconclusive
        pts = voxel_downsample(scan.points_base_xy(), 0.05)
        if len(pts) < 20:
            self.last_outcome = "few_points"
            return inconclusive
        res = icp_2d(pts, self._pts, pose_xytheta, target_tree=self._tree,
                     target_normals=self._normals, max_corr_dist_m=0.3, max_iter=f.align_max_iter,
                     kernel=f.align_kernel, kernel_scale_m=f.align_kernel_scale_m)
        if not res.converged or res.degenerate or res.fitness < f.align_min_fitness:
            self.last_outcome = ("not_converged" if not res.converged else "degenerate"
                                 if res.degenerate else "low_fitness")
            return inconclusive
        d, _ = self._tree.query(transform_points(res.T_target_source, pts),
                                distance_upper_bound=f.align_tight_m)
        self.last_tight_fraction = float(np.mean(np.isfinite(d)))
        corr = relative(pose_xytheta, res.T_target_source)
        ok = (np.hypot(corr[0], corr[1]) <= f.align_max_correction_m
              and abs(corr[2]) <= np.radians(f.align_max_correction_deg))
        self.last_verified = bool(ok)
        self.last_outcome = "confirmed" if ok else "contradicts"
        return (res.T_target_source if ok else pose_xytheta), bool(ok)


class Relocalizer:
    """``relocalize``: how well a pose explains a scan on the current map, and a correlative
    search (then ICP) for a better one around it. Base-frame points (N, 2) [m]; map poses
    (3,) [m, m, rad]."""

    def __init__(self, fusion: FusionConfig):
        self.fusion = fusion
        self._pts = self._tree = self._normals = self._field = None
        self._resolution_m = 0.05

    def set_grid(self, grid: OccupancyGrid, edges_xy: np.ndarray | None = None) -> None:
        """The map's edges (``edges_xy`` (M, 2), its :func:`_edge_points` if already worked
        out) and their tree, for :meth:`fit` on every update; the search's normals and field
        wait for the next :meth:`search` (a search is rare, a map change on a large map is
        not: building both on each change was a seventh of the stack's time on MIT CSAIL)."""
        from scipy.spatial import cKDTree

        self._pts = _edge_points(grid) if edges_xy is None else edges_xy
        self._tree = cKDTree(self._pts) if len(self._pts) >= 20 else None
        self._normals = self._field = None
        self._resolution_m = grid.resolution_m

    def _search_aids(self) -> None:
        """Build the normals and the likelihood field of the current map's edges, once per
        map, before a search."""
        from gatmo.scanmatch.correlative import likelihood_field
        from gatmo.scanmatch.icp import normals_of

        if self._field is None:
            self._normals, _ = normals_of(self._pts, self._tree)
            self._field = likelihood_field(self._pts, resolution_m=self._resolution_m,
                                           sigma_m=self.fusion.relocalize_fit_m)

    @property
    def ready(self) -> bool:
        return self._tree is not None

    def fit(self, pose_xytheta: np.ndarray, points_base_xy: np.ndarray) -> float:
        """Fraction of the points within ``relocalize_fit_m`` of a map edge at the pose."""
        if len(points_base_xy) == 0:
            return 0.0
        d, _ = self._tree.query(transform_points(pose_xytheta, points_base_xy),
                                distance_upper_bound=self.fusion.relocalize_fit_m)
        return float(np.mean(np.isfinite(d)))

    def search(self, pose_xytheta: np.ndarray, points_base_xy: np.ndarray,
               fit_here: float | None = None) -> np.ndarray | None:
        """A pose near ``pose_xytheta`` that explains at least ``relocalize_min_fit`` of the
        points, unambiguously; None if there is none. ``fit_here``: :meth:`fit` at
        ``pose_xytheta`` if already known."""
        from gatmo.scanmatch.correlative import MatchConfig, match_to_submap

        f = self.fusion
        self._search_aids()
        # a second peak counts as a rival place when it is 0.3 m away; a turn of the same
        # place (the search's heading steps) is no rival
        m = match_to_submap(points_base_xy, self._pts, pose_xytheta,
                            window_xy_m=f.relocalize_window_m,
                            window_theta_rad=np.radians(f.relocalize_window_deg),
                            cfg=MatchConfig(ambiguity_theta_rad=np.pi,
                                            ambiguity_ratio=f.relocalize_ambiguity_ratio),
                            field=self._field, target_tree=self._tree,
                            target_normals=self._normals)
        if not m.accepted:
            return None
        # a peak on the window's edge may be the slope of one beyond it (a wall slid along)
        d = np.abs(relative(pose_xytheta, m.search.T_target_source))
        if max(d[0], d[1]) >= f.relocalize_window_m - 0.1 or \
                d[2] >= np.radians(f.relocalize_window_deg) - np.radians(1.0):
            return None
        pose = np.asarray(m.T_target_source, dtype=float)
        if fit_here is None:
            fit_here = self.fit(pose_xytheta, points_base_xy)
        ok = self.fit(pose, points_base_xy) >= max(f.relocalize_min_fit,
                                                   fit_here + f.relocalize_min_gain)
        return pose if ok else None


@dataclass
class StackStep:
    """What one scan did. ``pose_xytheta`` is the published base pose in the map frame."""

    stamp_s: float
    pose_xytheta: np.ndarray
    localizer_pose_xytheta: np.ndarray
    cov: np.ndarray
    confident: bool
    reset: bool
    events: list = field(default_factory=list)
    map_changed: bool = False
    ms: float = 0.0
    # the base pose (map frame) handed to GATMO as trusted, after the scan-to-map alignment (so
    # it may differ from pose_xytheta); None: GATMO was not handed this scan as trusted
    gatmo_pose_xytheta: np.ndarray | None = None
    # that pose was confirmed by the scan-to-map alignment (GATMO's pose_verified: absence and
    # the nudge take only such scans)
    gatmo_pose_verified: bool = False
    # what the scan-to-map alignment concluded on this scan (one of ALIGN_OUTCOMES); None: it
    # did not run (no trusted pose, or align_to_map off)
    align_outcome: str | None = None
    # relocalize: the filter was started again on this scan (at localizer_pose_xytheta)
    relocalized: bool = False


def _wheels_still(step_xytheta: np.ndarray) -> bool:
    """The wheels' step (3,) is exactly no motion: a stall, or the robot standing."""
    return not np.any(np.abs(step_xytheta) > 1e-9)


def _wrapped(pose_xytheta) -> np.ndarray:
    """A new (3,) pose array with the heading wrapped to [-pi, pi)."""
    return np.array([pose_xytheta[0], pose_xytheta[1], float(wrap_angle(pose_xytheta[2]))])


def _startable_at(filt, pose_xytheta) -> bool:
    """A particle filter may be started again at ``pose_xytheta`` (3,): its ``start_refusal``
    has nothing against it (a lost filter's pose can be in a wall: the 50-run soak, chain 12).
    A filter that gives no reasons (a test's stand-in) may anywhere."""
    refusal = getattr(filt, "start_refusal", None)
    return refusal is None or refusal(pose_xytheta) is None


def _injected(localizer) -> int:
    """Random particles the localizer has injected so far (AMCL's recovery; 0 if it does not
    count them)."""
    return getattr(getattr(localizer, "stats", None), "random_injected", 0)


def blend_poses(a_xytheta: np.ndarray, b_xytheta: np.ndarray, std_a_m: float,
                std_b_m: float) -> np.ndarray:
    """The inverse-variance weighted mean (3,) of two map poses (x, y, theta) with isotropic
    standard deviations ``std_a_m`` and ``std_b_m``; the heading is averaged on the circle
    with the same weights."""
    w = std_b_m**2 / (std_a_m**2 + std_b_m**2)  # the weight of a
    a = np.asarray(a_xytheta, dtype=float)
    b = np.asarray(b_xytheta, dtype=float)
    d = a - b
    d[2] = wrap_angle(d[2])
    return _wrapped(b + w * d)


def is_confident(estimate, fusion: FusionConfig, *, strict: bool = False,
                 require_update: bool = True) -> bool:
    """The paper's reset test on the particle covariance (Sec. IV-B); ``strict`` applies the
    tighter thresholds GATMO's absence test needs; ``require_update``: only on a scan the
    filter weighed (otherwise its last covariance counts)."""
    if require_update and not getattr(estimate, "updated", True):
        return False
    cov = np.asarray(estimate.cov, dtype=float)
    if not np.all(np.isfinite(cov)):
        return False
    std_xy = float(np.sqrt(max(cov[0, 0], cov[1, 1], 0.0)))
    std_th = float(np.degrees(np.sqrt(max(cov[2, 2], 0.0))))
    if strict:
        return (std_xy <= fusion.absence_max_std_xy_m
                and std_th <= fusion.absence_max_std_theta_deg)
    return std_xy <= fusion.reset_max_std_xy_m and std_th <= fusion.reset_max_std_theta_deg


class LocalizationStack:
    """Localizer, optional scan matcher and optional GATMO mapper, stepped scan by scan.

    Args:
        localizer: a :class:`gatmo.localization.mcl.MonteCarloLocalizer` (or anything with
            ``update(odom_pose_xytheta, scan[, withheld]) -> PoseEstimate`` and
            ``update_map_region(cells_new, ix0, iy0)``).
        matcher: a scan matcher with ``register(scan) -> MatchResult`` whose ``pose_xytheta`` is
            the base pose in the matcher's own frame, or None (localizer pose published as is).
        mapper: a :class:`gatmo.objects.mapper.GatmoMapper` or None (static map).
        fusion: reset thresholds.
        initial_pose_xytheta: the pose (map frame, (3,)) each run is started from, or None
            (global localization); with ``fusion.publish_blend_from_start`` it is published,
            carried by the wheels, until the run's first tight confirmation.
        initial_std_m: its position standard deviation [m] (the initial cloud's).
    """

    def __init__(self, localizer, matcher=None, mapper=None, fusion: FusionConfig | None = None,
                 loc_grid: OccupancyGrid | None = None, anchor=None,
                 initial_pose_xytheta: np.ndarray | None = None, initial_std_m: float = 0.1):
        self.localizer = localizer
        # fusion.anchor_filter: the second filter (flat sensor model, same map, raw scans), and
        # the localizer's updates in a row on which the two have parted
        self.anchor = anchor
        self._anchor_apart = 0
        # (localizer pose, anchor pose, odometry) at the last update the two agreed on
        self._anchor_ref: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self.anchor_restarts = 0  # the anchor started again at the localizer's pose
        self.anchor_gated = 0  # scans kept from GATMO as the two filters disagreed
        # a fixed map for the localizer, the alignment and the relocalizer (a second pass,
        # ``fusion.passes``); None: GATMO's current map, updated as it changes
        self.loc_grid = loc_grid
        self.matcher = matcher
        self.mapper = mapper
        self.fusion = fusion or FusionConfig()
        self.T_map_match: np.ndarray | None = None
        self._travel_since_reset_m = np.inf
        self._last_pose: np.ndarray | None = None
        self.resets: list[tuple[float, str, np.ndarray]] = []  # (stamp_s, why, pose)
        self.n_scans = 0
        self.n_map_updates = 0
        self.n_masked = 0  # returns withheld from the localizer (mask_unexplained)
        self._aligner: MapAligner | None = None
        self._last_loc: np.ndarray | None = None
        self._last_odom: np.ndarray | None = None
        self._last_precise = False  # the last estimate passed GATMO's strict confidence test
        self._settle_left_m = 0.0
        # confirmations since a stack restart (settle_until_confirmed); None: none pending
        self._settle_confirmed: int | None = None
        self._injected_seen = 0  # the localizer's random particles counted so far
        self._offset_beams: np.ndarray | None = None  # see _masked
        # a localizer without the ``withheld`` argument (an older stand-in) gets the masked
        # scan alone
        try:
            params = inspect.signature(getattr(localizer, "update", None)).parameters
            self._takes_withheld = "withheld" in params or any(
                p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values())
        except (TypeError, ValueError):  # no update (a stand-in stepped otherwise)
            self._takes_withheld = False
        # publish_pose aligned: the last confirmed (map pose, odometry pose, its own standard
        # deviation [m]) it is carried from
        self._published_anchor: tuple[np.ndarray, np.ndarray, float] | None = None
        # publish_blend_from_start: the pose (map frame) each run is started from and its
        # standard deviation [m]; None: not given (global localization)
        self.initial_pose_xytheta = (None if initial_pose_xytheta is None
                                     else _wrapped(initial_pose_xytheta))
        self.initial_std_m = float(initial_std_m)
        # the run's last alignment outcome (publish_blend_suspect_std_m); None: none yet
        self._last_align_outcome: str | None = None
        # relocalize: the search (rebuilt when the map changed), the last found pose with the
        # odometry it was found at and how many updates in a row agreed, and the restarts
        self._reloc: Relocalizer | None = None
        self._reloc_stale = True
        # the current map (a copy) and its edge points, shared by the alignment and the
        # relocalizer; None: work them out again (the map changed)
        self._edges: tuple[OccupancyGrid, np.ndarray] | None = None
        self._reloc_found: tuple[np.ndarray, np.ndarray, int] | None = None
        # odometry at the last update, and the travel since the filter last fitted the map
        self._reloc_odom: np.ndarray | None = None
        self._reloc_travel_m = 0.0
        self.relocalizations: list[tuple[float, np.ndarray, np.ndarray]] = []  # (stamp, from, to)
        # publish_through_stalls: (wheels, matcher pose) at the last scan, and the matcher's
        # motion (base frame) since the wheels last moved
        self._stall_prev: tuple[np.ndarray, np.ndarray] | None = None
        self._stall_motion = np.zeros(3)
        # carry_matcher_inflation: the carrying odometry's pose, (wheels, matcher pose) at the
        # last scan, and whether the wheels stood exactly still there
        self._carry: np.ndarray | None = None
        self._carry_prev: tuple[np.ndarray, np.ndarray] | None = None
        self._carry_stalled = False
        # carry_matcher_inflation: the inflations carried with (K,: carry_adapt_inflations'
        # and carry_matcher_inflation, or this one alone), each one's carried pose (K, 3),
        # the wheels' travel so far [m], the forgotten sums of squared error (K,), the pairs
        # scored, the travel at the last scoring, the one published, and the confirmations
        # kept to score from: (pose, carries, travel)
        f = self.fusion
        infl = {f.carry_matcher_inflation} | set(f.carry_adapt_inflations or ())
        self._carry_inflations = np.array(sorted(float(x) for x in infl if x is not None))
        self._carry_adapt = f.carry_adapt_inflations is not None and len(infl) > 1
        self._carry_choice = int(np.searchsorted(self._carry_inflations,
                                                 f.carry_matcher_inflation or 0.0))
        self._carry_travel_m = 0.0
        self._carry_sq = np.zeros(len(self._carry_inflations))
        self._carry_scored = 0
        self._carry_scored_at_m = 0.0
        self._carry_refs: list[tuple[np.ndarray, np.ndarray, float]] = []

    def begin_run(self, run_id: int) -> None:
        """Start a new log: the matcher's frame is new, the object map carries over."""
        self.T_map_match = None
        self._travel_since_reset_m = np.inf
        self._last_pose = None
        self._last_loc = self._last_odom = None
        self._last_precise = False
        self._settle_left_m = 0.0
        self._settle_confirmed = None
        self._published_anchor = None
        self._last_align_outcome = None
        self._reloc_found = None
        self._reloc_stale = True
        self._edges = None
        self._reloc_odom, self._reloc_travel_m = None, 0.0
        self._anchor_apart = 0
        self._anchor_ref = None
        self._injected_seen = _injected(self.localizer)
        self._stall_prev, self._stall_motion = None, np.zeros(3)
        self._carry = self._carry_prev = None
        self._carry_stalled = False
        self._carry_refs = []
        if self.mapper is not None:
            self.mapper.begin_run(run_id)

    def _carry_pose(self, odom: np.ndarray, match) -> np.ndarray:
        """The odometry the published pose is carried by (3,): the wheels' ``odom``, or with
        ``carry_matcher_inflation`` the wheels' pose at the run's first scan composed with each
        step's information-weighted average of the wheels' and the ICP step (with
        ``carry_adapt_inflations``, the one of the inflations tried that scores best)."""
        f = self.fusion
        if f.carry_matcher_inflation is None or match is None:
            return odom
        infl = self._carry_inflations
        mpose = np.asarray(match.pose_xytheta, dtype=float)
        if self._carry is None:
            self._carry = np.tile(odom, (len(infl), 1))
        else:
            w_odom, w_match = self._carry_prev
            dw = relative(w_odom, odom)
            steps = np.tile(dw, (len(infl), 1))
            still = _wheels_still(dw)
            # through a stall (the wheels exactly still) and at the wheels' catch-up the carry
            # takes the wheels' steps: the matcher falls back on the wheels at a catch-up too
            # far from its guess, which would count the stall's motion twice, and moving the
            # published pose through a stall is publish_through_stalls' job
            stall = still or self._carry_stalled
            self._carry_stalled = still
            cov = np.asarray(match.cov, dtype=float)
            if match.used_icp and not stall and np.all(np.isfinite(cov)):
                dm = relative(w_match, mpose)
                # the pose's covariance (matcher frame) turned into the base frame
                c, s = np.cos(mpose[2]), np.sin(mpose[2])
                R = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
                t, r = float(np.hypot(dw[0], dw[1])), abs(float(dw[2]))
                st = f.carry_wheel_std_per_m * t + 0.2 * f.carry_wheel_std_per_rad * r + 2e-3
                sr = f.carry_wheel_std_per_rad * r + 0.15 * f.carry_wheel_std_per_m * t + 2e-3
                iw = np.diag([st**-2, st**-2, sr**-2])
                cov_base = R @ cov @ R.T
                for k, x in enumerate(infl):
                    im = np.linalg.inv(cov_base * x + np.diag([1e-6, 1e-6, 1e-8]))
                    steps[k] = np.linalg.solve(im + iw, im @ dm + iw @ dw)
            for k in range(len(infl)):
                self._carry[k] = compose(self._carry[k], steps[k])
            self._carry_travel_m += float(np.hypot(dw[0], dw[1]))
        self._carry_prev = (odom.copy(), mpose.copy())
        return self._carry[self._carry_choice].copy()

    def _score_carries(self, confirmed: np.ndarray) -> None:
        """``carry_adapt_inflations``: a tight confirmation (3,) scores each carry's pose
        carried from the earlier confirmations kept, and the best-scoring carry is published
        from here on."""
        if self._carry is None:
            return
        f = self.fusion
        now = self._carry_travel_m
        self._carry_refs = [r for r in self._carry_refs if now - r[2] <= f.carry_adapt_max_m]
        if now - self._carry_scored_at_m >= f.carry_adapt_spacing_m:
            pairs = [r for r in self._carry_refs if now - r[2] >= f.carry_adapt_spacing_m]
            if pairs:
                self._carry_sq *= 0.5 ** ((now - self._carry_scored_at_m)
                                          / f.carry_adapt_halflife_m)
                for c_ref, carries_ref, _ in pairs:
                    for k in range(len(self._carry_inflations)):
                        e = relative(confirmed, compose(c_ref, relative(carries_ref[k],
                                                                        self._carry[k])))
                        self._carry_sq[k] += e[0] ** 2 + e[1] ** 2 + e[2] ** 2  # 1 m/rad
                self._carry_scored += len(pairs)
                self._carry_scored_at_m = now
                if self._carry_scored >= f.carry_adapt_min_pairs:
                    self._carry_choice = int(np.argmin(self._carry_sq))
        if not self._carry_refs or now - self._carry_refs[-1][2] >= f.carry_adapt_spacing_m:
            self._carry_refs.append((np.array(confirmed, dtype=float), self._carry.copy(), now))

    @property
    def carry_inflation(self) -> float | None:
        """The scan matcher's covariance inflation the published pose is carried with now
        (``carry_adapt_inflations``' choice, else ``carry_matcher_inflation``)."""
        if self.fusion.carry_matcher_inflation is None:
            return None
        return float(self._carry_inflations[self._carry_choice])

    def _through_stall(self, scan: Scan, match) -> np.ndarray:
        """``publish_through_stalls``: the matcher's motion (3,) (base frame) since the wheels
        last reported any, while they report none (zeros otherwise)."""
        if not self.fusion.publish_through_stalls or match is None:
            return np.zeros(3)
        wheels = np.asarray(scan.odom_pose_xytheta, dtype=float)
        m = np.asarray(match.pose_xytheta, dtype=float)
        if self._stall_prev is not None:
            still = _wheels_still(relative(self._stall_prev[0], wheels))
            if not still:
                self._stall_motion = np.zeros(3)
            elif match.used_icp:
                self._stall_motion = compose(self._stall_motion,
                                             relative(self._stall_prev[1], m))
        self._stall_prev = (wheels, m)
        return self._stall_motion

    def _fits(self, points_base_xy: np.ndarray, *poses_xytheta: np.ndarray) -> list[float]:
        """Per pose, the fraction of the points (N, 2) (base frame, 5 cm voxels) within
        ``relocalize_fit_m`` of an edge of the current map (:meth:`Relocalizer.fit`; 0 on a
        map without edges)."""
        reloc = self._relocalizer()
        return [reloc.fit(p, points_base_xy) if reloc.ready else 0.0 for p in poses_xytheta]

    def _relocalizer(self) -> Relocalizer:
        """The relocalizer's fit and search on the current map (built on first use, its map
        refreshed after a change)."""
        if self._reloc is None:
            self._reloc = Relocalizer(self.fusion)
        if self._reloc_stale:
            self._reloc.set_grid(*self._map_edges())
            self._reloc_stale = False
        return self._reloc

    def _map_edges(self) -> tuple[OccupancyGrid, np.ndarray]:
        """The current map (a copy) and its :func:`_edge_points`, worked out once per change
        of the map for the alignment and the relocalizer both."""
        if self._edges is None:
            grid = self._map_grid()
            self._edges = (grid, _edge_points(grid))
        return self._edges

    def _restart_cov(self) -> np.ndarray:
        """(3, 3) covariance of a filter started again by the stack (relocalize_std_*)."""
        s_xy, s_th = self.fusion.relocalize_std_xy_m, np.radians(self.fusion.relocalize_std_deg)
        return np.diag([s_xy**2, s_xy**2, s_th**2])

    def _anchor_start(self, scan: Scan) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """Where the two filters stand before their first update of a run or after a restart
        (the pose they were started at), with the odometry of ``scan``: the poses they last
        agreed on, from which :meth:`_parted_from_anchor` measures who strayed. None if either
        was not started at a pose (global localization), or cannot tell."""
        if not all(callable(getattr(f, "estimate", None)) for f in (self.localizer, self.anchor)):
            return None  # a localizer that cannot say where it stands
        (p_loc, c_loc), (p_anchor, c_anchor) = self.localizer.estimate(), self.anchor.estimate()
        # a cloud spread over the map has no pose to stray from
        if max(c_loc[0, 0] + c_loc[1, 1], c_anchor[0, 0] + c_anchor[1, 1]) > 1.0:
            return None
        return (_wrapped(np.asarray(p_loc, dtype=float)),
                _wrapped(np.asarray(p_anchor, dtype=float)),
                np.asarray(scan.odom_pose_xytheta, dtype=float).copy())

    def _strayed_m(self, loc_pose: np.ndarray, anchor_pose: np.ndarray,
                   odom: np.ndarray) -> tuple[float, float]:
        """How far [m] the localizer at ``loc_pose`` and the anchor at ``anchor_pose`` have
        moved against the wheels (odometry ``odom``) since they last agreed
        (``_anchor_ref``, which must be set)."""
        ref_loc, ref_anchor, ref_odom = self._anchor_ref
        d_odom = relative(ref_odom, odom)
        return (float(np.hypot(*(compose(ref_loc, d_odom)[:2] - loc_pose[:2]))),
                float(np.hypot(*(compose(ref_anchor, d_odom)[:2] - anchor_pose[:2]))))

    def _anchor_if_apart(self, loc_pose: np.ndarray, odom: np.ndarray,
                         scan: Scan) -> np.ndarray | None:
        """``publish_anchor_when_apart``: the anchor's pose (3,) if the two filters are more
        than ``anchor_agree_m`` apart, the localizer has strayed from the wheels more than
        the anchor since they last agreed, and the anchor's pose explains ``scan`` nearly as
        well (``anchor_fit_margin``, as for a restart); else None."""
        if self._anchor_ref is None:
            return None
        a = _wrapped(np.asarray(self.anchor.estimate()[0], dtype=float))
        if np.hypot(*(a[:2] - loc_pose[:2])) <= self.fusion.anchor_agree_m:
            return None
        strayed_loc, strayed_anchor = self._strayed_m(loc_pose, a, odom)
        if strayed_loc <= strayed_anchor:
            return None
        return a if self._anchor_fits(scan, a, loc_pose) else None

    def _anchor_fits(self, scan: Scan, anchor_pose: np.ndarray, loc_pose: np.ndarray) -> bool:
        """The anchor's pose explains ``scan`` nearly as well as the localizer's: at most
        ``anchor_fit_margin`` less of it within ``relocalize_fit_m`` of the map. A filter
        correcting itself moves against the wheels too (on MIT CSAIL the localizer was the
        one right in every such parting, and the anchor's pose explained 0.05-0.78 of the
        scan against its 0.5-1.0)."""
        from gatmo.scanmatch.icp import voxel_downsample

        fit_a, fit_loc = self._fits(voxel_downsample(scan.points_base_xy(), 0.05), anchor_pose,
                                    loc_pose)
        return fit_a >= fit_loc - self.fusion.anchor_fit_margin

    def _parted_from_anchor(self, est, loc_pose: np.ndarray, anchor_est,
                            odom: np.ndarray, scan: Scan) -> np.ndarray | None:
        """The anchor filter's pose (3,) if the localizer has parted from it (more than
        ``anchor_gap_m`` on ``anchor_gap_updates`` of its updates in a row, counted on this one)
        and moved against odometry since they last agreed by ``anchor_odom_margin_m`` more than
        the anchor did, and the anchor's pose explains ``scan`` nearly as well
        (``anchor_fit_margin``); else None. Where the anchor is the one that moved more, it is
        started again at the localizer's pose."""
        if not getattr(est, "updated", True):
            return None
        f = self.fusion
        a = _wrapped(np.asarray(anchor_est.pose_xytheta, dtype=float))
        gap = float(np.hypot(*(a[:2] - loc_pose[:2])))
        if gap <= f.anchor_agree_m or self._anchor_ref is None:
            self._anchor_ref = (loc_pose.copy(), a, odom.copy())
        if gap <= f.anchor_gap_m:
            self._anchor_apart = 0
            return None
        self._anchor_apart += 1
        if self._anchor_apart < f.anchor_gap_updates:
            return None
        self._anchor_apart = 0
        strayed_loc, strayed_anchor = self._strayed_m(loc_pose, a, odom)
        if strayed_loc > strayed_anchor + f.anchor_odom_margin_m:
            # a filter may stray from the wheels to correct itself: the anchor's pose must also
            # explain the scan nearly as well as the localizer's
            if not self._anchor_fits(scan, a, loc_pose):
                return None
            if not _startable_at(self.localizer, a):
                return None
            return a  # the caller restarts the localizer there (_restart_at)
        if strayed_anchor <= strayed_loc + f.anchor_odom_margin_m:
            return None  # neither strayed clearly more: both stay
        if not _startable_at(self.anchor, loc_pose):
            return None  # (a lost localizer's pose can be in a wall: that is no place to go)
        self.anchor.set_initial_pose(loc_pose, self._restart_cov())
        self.anchor_restarts += 1
        self._anchor_ref = (loc_pose.copy(), loc_pose.copy(), odom.copy())
        return None

    def _settle_after_restart(self, pose_xytheta: np.ndarray, scan: Scan) -> None:
        """``settle_until_confirmed``: while GATMO waits after a stack restart, align the
        strictly confident pose ``pose_xytheta`` (3,) to the map; once that many alignments
        confirmed it, the wait ends (on this scan)."""
        _, ok = self._map_aligner().refine(pose_xytheta, scan)
        if ok:
            self._settle_confirmed += 1
            if self._settle_confirmed >= self.fusion.settle_confirmed_poses:
                self._settle_left_m, self._settle_confirmed = 0.0, None

    def _map_aligner(self) -> MapAligner:
        """The scan-to-map alignment on the current map (built on first use; the step hands
        it each map change)."""
        if self._aligner is None:
            self._aligner = MapAligner(self.fusion)
            self._aligner.set_grid(*self._map_edges())
        return self._aligner

    def _anchor_disagrees(self, anchor_est, loc_pose: np.ndarray) -> bool:
        """``anchor_gates_gatmo``: the anchor filter's pose is more than ``anchor_gate_gap_m``
        from the localizer's ``loc_pose`` (3,) on this scan. On hall seeds 403, 405 and 412,
        of the scans GATMO was handed with a pose 0.2 m or more off, 83-100 % were more than
        0.15 m apart; of those within 0.1 m, 1-2 % (docs/experiments.md, forty-fifth
        session)."""
        if anchor_est is None or not self.fusion.anchor_gates_gatmo:
            return False
        a = np.asarray(anchor_est.pose_xytheta, dtype=float)
        return bool(np.hypot(*(a[:2] - loc_pose[:2])) > self.fusion.anchor_gate_gap_m)

    def _restart_at(self, pose_xytheta: np.ndarray, stamp_s: float,
                    from_xytheta: np.ndarray) -> None:
        """Start the localizer again at a pose the stack found (relocalize_std_*), recorded in
        :attr:`relocalizations` with the pose it leaves; GATMO waits as after any jump, and the
        matcher and the published pose are re-anchored."""
        self.relocalizations.append((float(stamp_s), from_xytheta.copy(), pose_xytheta.copy()))
        self.localizer.set_initial_pose(pose_xytheta, self._restart_cov())
        self._settle_left_m = self.fusion.settle_after_jump_m
        self._settle_confirmed = 0
        self.T_map_match = None
        self._published_anchor = None
        # the anchor filter's reference starts again here: the jump is no straying
        self._anchor_ref, self._anchor_apart = None, 0

    def _apply_map_changes(self) -> bool:
        """Hand GATMO's queued region updates to the localizer; True if there were any."""
        changes = self.mapper.pop_map_changes()
        if self.loc_grid is not None:
            return False  # the localizer keeps its fixed map
        for cells_new, ix0, iy0 in changes:
            self.localizer.update_map_region(cells_new, ix0, iy0)
            if self.anchor is not None:
                self.anchor.update_map_region(cells_new, ix0, iy0)
        self.n_map_updates += len(changes)
        return bool(changes)

    def _map_grid(self) -> OccupancyGrid:
        """The map the localizer, the alignment and the relocalizer use."""
        return self.loc_grid if self.loc_grid is not None else self.mapper.grid()

    def step(self, scan: Scan) -> StackStep:
        """Process one scan; see the module docstring for the order of work."""
        t0 = time.perf_counter()
        match = self.matcher.register(scan) if self.matcher is not None else None
        stall_motion = self._through_stall(scan, match)
        masked, withheld = self._masked(scan)
        if self.anchor is not None and self._anchor_ref is None:
            self._anchor_ref = self._anchor_start(scan)
        anchor_est = (self.anchor.update(scan.odom_pose_xytheta, scan)
                      if self.anchor is not None else None)
        if self._takes_withheld:
            est = self.localizer.update(scan.odom_pose_xytheta, masked, withheld=withheld)
        else:
            est = self.localizer.update(scan.odom_pose_xytheta, masked)
        loc_pose = np.asarray(est.pose_xytheta, dtype=float)
        confident = is_confident(est, self.fusion)
        odom = np.asarray(scan.odom_pose_xytheta, dtype=float)
        carry = self._carry_pose(odom, match)
        if (self._last_loc is None and self.initial_pose_xytheta is not None
                and self.fusion.publish_blend_from_start and self.fusion.publish_blend):
            # the run's first scan: the given start pose, carried until the first tight
            # confirmation (a restart of the filter drops it, as it drops a confirmed pose)
            self._published_anchor = (self.initial_pose_xytheta.copy(), carry.copy(),
                                      self.initial_std_m)
        if self._last_loc is not None:
            d_odom = relative(self._last_odom, odom)
            # the wait counts the wheels' travel: the jump itself is no travel
            self._settle_left_m = max(0.0, self._settle_left_m - float(np.hypot(*d_odom[:2])))
            jump = relative(compose(self._last_loc, d_odom), loc_pose)
            if np.hypot(jump[0], jump[1]) > self.fusion.max_offset_jump_m:
                self._settle_left_m = self.fusion.settle_after_jump_m
                self._settle_confirmed = None  # the filter jumped by itself: the full wait
        # AMCL's recovery injected random particles: the scans fit the filter's own cloud
        # poorly, so it suspects it is lost, and whatever it settles on next is a guess
        injected = _injected(self.localizer)
        if injected > self._injected_seen:
            self._settle_left_m = self.fusion.settle_after_jump_m
            self._settle_confirmed = None
        self._injected_seen = injected
        relocalized = False
        # only a confident filter (the paper's reset test) is suspected of being confident and
        # wrong: a broad cloud still reaches the right place by itself
        if (self.fusion.relocalize and confident
                and callable(getattr(self.mapper, "grid", None))
                and callable(getattr(self.localizer, "set_initial_pose", None))):
            found = self._relocalized(masked, loc_pose, odom)
            if found is not None and not _startable_at(self.localizer, found):
                found = None
            relocalized = found is not None
        if anchor_est is not None and not relocalized:
            found = self._parted_from_anchor(est, loc_pose, anchor_est, odom, scan)
            relocalized = found is not None
        if relocalized:
            self._restart_at(found, scan.stamp_s, loc_pose)
            loc_pose = found
        self._last_loc, self._last_odom = loc_pose, odom
        self._last_precise = is_confident(est, self.fusion, strict=True, require_update=False)
        reset = False
        pose = loc_pose
        if match is not None:
            T_match_base = np.asarray(match.pose_xytheta, dtype=float)
            if self.T_map_match is None or confident:
                # the paper's reset: the matcher's frame is re-anchored on the filter's estimate;
                # offset_gain < 1 moves it only part of the way (a complementary filter: the
                # matcher's precise increments average the filter's jitter out)
                target = compose(loc_pose, inverse(T_match_base))
                g = 1.0 if self.T_map_match is None else self.fusion.offset_gain
                if g >= 1.0:
                    self.T_map_match = target
                else:
                    d = relative(self.T_map_match, target)
                    self.T_map_match = compose(self.T_map_match, d * g)
                reset = True
                why = "confident" if confident else "start"
                self.resets.append((float(scan.stamp_s), why, loc_pose.copy()))
                if confident:
                    self._travel_since_reset_m = 0.0
            pose = compose(self.T_map_match, T_match_base)
            # A fused pose far from the localizer means the matcher diverged (e.g. people filled
            # the scan), and an offset not confirmed for a while has drifted with the matcher:
            # fall back to the localizer.
            gap = relative(pose, loc_pose)
            stale = self._travel_since_reset_m > self.fusion.max_travel_without_reset_m
            if np.hypot(gap[0], gap[1]) > self.fusion.max_offset_jump_m or stale:
                self.T_map_match = compose(loc_pose, inverse(T_match_base))
                pose = loc_pose
                reset = True
                if not stale:  # stale fallbacks repeat every scan: not logged
                    self.resets.append((float(scan.stamp_s), "diverged", loc_pose.copy()))
        elif confident:
            self._travel_since_reset_m = 0.0
        if self._last_pose is not None:
            self._travel_since_reset_m += float(np.hypot(*(pose[:2] - self._last_pose[:2])))
        self._last_pose = pose.copy()
        pose = _wrapped(pose)

        events: list = []
        changed = False
        gatmo_pose = None
        verified = False
        align_outcome = publish_outcome = publish_confirmed = None
        if self.mapper is not None:
            # the filter updates only every update_min_d of travel; between its confident
            # updates the matcher's pose stays precise for a while (confident_for_m), and the
            # scan-to-map alignment below checks every such pose directly
            aligned_scan = (self._alignment_scan(scan, masked, withheld)
                            if self.fusion.align_masked == "all" else scan)
            pose_ok = is_confident(est, self.fusion, strict=True) or (
                self._travel_since_reset_m <= self.fusion.confident_for_m)
            if (self._settle_left_m > 0.0 and pose_ok and self._settle_confirmed is not None
                    and self.fusion.settle_until_confirmed and self.fusion.align_to_map):
                self._settle_after_restart(pose, aligned_scan)
            pose_ok = pose_ok and self._settle_left_m <= 0.0
            if pose_ok and self._anchor_disagrees(anchor_est, loc_pose):
                pose_ok = False
                self.anchor_gated += 1
            map_pose = pose
            verified = pose_ok
            if pose_ok and self.fusion.align_to_map:
                aligner = self._map_aligner()
                map_pose, pose_ok = aligner.refine(pose, aligned_scan)
                verified = aligner.last_verified
                align_outcome = publish_outcome = aligner.last_outcome
                publish_confirmed = self._tight_confirmed(map_pose)
                masked_scan = (self._alignment_scan(scan, masked, withheld)
                               if self.fusion.align_masked == "publish" else scan)
                if masked_scan is not scan:
                    # the returns the localizer does not weigh pull the alignment too; GATMO
                    # keeps the full scan's verdict (docs/experiments.md, sixty-first session)
                    masked_pose, _ = aligner.refine(pose, masked_scan)
                    publish_outcome = aligner.last_outcome
                    publish_confirmed = self._tight_confirmed(masked_pose)
            if pose_ok:
                map_pose = gatmo_pose = np.array(map_pose, dtype=float)
            events = self.mapper.update(map_pose, scan, pose_confident=pose_ok,
                                        stamp_s=scan.stamp_s, pose_verified=verified)
            changed = self._apply_map_changes()
            if changed:
                self._edges = None
            if changed and self._aligner is not None:
                self._aligner.set_grid(*self._map_edges())
            self._reloc_stale = self._reloc_stale or changed
        self.n_scans += 1
        if publish_outcome is not None:
            self._last_align_outcome = publish_outcome
        published = _wrapped(loc_pose)
        if self.fusion.publish_pose == "fused":
            published = pose
        elif self.fusion.publish_pose == "aligned":
            if publish_confirmed is not None and self._carry_adapt and self._carry is not None:
                self._score_carries(publish_confirmed)
                carry = self._carry[self._carry_choice].copy()
            published = self._aligned_pose(published, carry, publish_confirmed)
        if self.anchor is not None and self.fusion.publish_anchor_when_apart:
            # the sharp filter slides onto moved furniture before the anchor test restarts it
            # (docs/experiments.md, forty-seventh session): report the anchor meanwhile
            a = self._anchor_if_apart(loc_pose, odom, scan)
            if a is not None:
                published = a
        if stall_motion.any():
            published = compose(published, stall_motion)
        return StackStep(
            stamp_s=float(scan.stamp_s),
            pose_xytheta=published,
            localizer_pose_xytheta=loc_pose,
            cov=np.asarray(est.cov, dtype=float),
            confident=confident,
            reset=reset,
            events=list(events),
            map_changed=changed,
            ms=(time.perf_counter() - t0) * 1e3,
            gatmo_pose_xytheta=gatmo_pose,
            gatmo_pose_verified=bool(gatmo_pose is not None and verified),
            align_outcome=align_outcome,
            relocalized=relocalized,
        )

    def _relocalized(self, scan: Scan, loc_pose: np.ndarray,
                     odom: np.ndarray) -> np.ndarray | None:
        """``relocalize``: the pose to start the filter again at after this update, or None."""
        from gatmo.scanmatch.icp import voxel_downsample

        f = self.fusion
        self._relocalizer()
        if self._reloc_odom is not None:
            self._reloc_travel_m += float(np.hypot(*relative(self._reloc_odom, odom)[:2]))
        self._reloc_odom = odom.copy()
        pts = voxel_downsample(scan.points_base_xy(), 0.05)
        found = None
        if self._reloc.ready and len(pts) >= f.relocalize_min_points:
            fit = self._reloc.fit(loc_pose, pts)
            if fit >= f.relocalize_min_fit:  # the filter fits the map here
                self._reloc_travel_m = 0.0
            if fit <= f.relocalize_below_fit and self._expects_enough(scan, loc_pose):
                found = self._reloc.search(loc_pose, pts, fit)
        if found is None:
            self._reloc_found = None
            return None
        n = 1
        if self._reloc_found is not None:  # the same place as last time, after odometry?
            prev, prev_odom, k = self._reloc_found
            d = relative(compose(prev, relative(prev_odom, odom)), found)
            if np.hypot(d[0], d[1]) <= 0.2 and abs(d[2]) <= np.radians(5.0):
                n = k + 1
        self._reloc_found = (found, odom.copy(), n)
        jump = float(np.hypot(*(found[:2] - loc_pose[:2])))
        reach = f.relocalize_max_jump_m + f.relocalize_max_jump_per_m * self._reloc_travel_m
        if n < f.relocalize_scans or not f.relocalize_min_shift_m <= jump <= reach:
            return None
        self._reloc_found = None
        self._reloc_travel_m = 0.0
        return found

    def _expects_enough(self, scan: Scan, loc_pose: np.ndarray) -> bool:
        """``relocalize_min_expected_beams``: whether the current map, ray-cast from the
        filter's pose, expects that many of the scan's beams to end on an occupied cell within
        the laser's range (and so could show the pose wrong). Unknown cells hold nothing to
        fit, so rays pass them."""
        f = self.fusion
        if f.relocalize_min_expected_beams <= 0:
            return True
        from gatmo.maps.raycast import cast_rays

        expected = cast_rays(self._map_grid(), compose(loc_pose, scan.laser_pose_xytheta),
                             scan.angles_rad, scan.range_max_m, stop_at_unknown=False)
        return int(np.sum(expected < scan.range_max_m)) >= f.relocalize_min_expected_beams

    def _masked(self, scan: Scan) -> tuple[Scan, np.ndarray | None]:
        """The scan with the returns GATMO cannot explain set to NaN (``mask_unexplained``),
        placed from the last localizer pose moved by odometry, and which beams (B,) bool were
        withheld (None: none)."""
        self._offset_beams = None  # (align_masked) the offset objects' beams (B,) bool
        unexplained_at = getattr(self.mapper, "unexplained_at", None)
        if unexplained_at is None or not self.fusion.mask_unexplained:
            return scan, None
        if self._last_loc is None:
            return scan, None
        odom = np.asarray(scan.odom_pose_xytheta, dtype=float)
        pred = compose(self._last_loc, relative(self._last_odom, odom))
        lp = compose(pred, scan.laser_pose_xytheta)
        valid = scan.valid
        if not valid.any():
            return scan, None
        a = lp[2] + scan.angles_rad[valid]
        r = scan.ranges_m[valid]
        pts = lp[:2] + r[:, None] * np.stack([np.cos(a), np.sin(a)], axis=1)
        bad = unexplained_at(pts)
        if self.fusion.mask_withheld:
            bad |= self.mapper.withheld_at(pts)
        if self.fusion.mask_offset_objects and self._last_precise:
            offset = self.mapper.offset_at(pts)
            if offset.any() and self.fusion.align_masked != "off":
                self._offset_beams = np.zeros(scan.num_beams, dtype=bool)
                self._offset_beams[np.nonzero(valid)[0][offset & ~bad]] = True
            bad |= offset
        self.n_masked += int(bad.sum())
        if not bad.any():
            return scan, None
        withheld = np.zeros(scan.num_beams, dtype=bool)
        withheld[np.nonzero(valid)[0][bad]] = True
        ranges = scan.ranges_m.copy()
        ranges[withheld] = np.nan
        return replace(scan, ranges_m=ranges), withheld

    def _alignment_scan(self, scan: Scan, masked: Scan, withheld: np.ndarray | None) -> Scan:
        """``align_masked``: the scan the alignment is handed, ``masked`` (``withheld`` (B,)
        bool or None: its withheld beams) with the returns of objects that miss it by an
        offset (``offset_at``) put back: where the map is right they are the scan's evidence
        that the pose is off (withheld too, the halls' ATE before anything moved rose 0.029 ->
        0.030 m; docs/experiments.md, sixty-first session). ``scan`` itself where no other
        returns were withheld."""
        if withheld is None:
            return scan
        if self._offset_beams is None:
            return masked
        if not (withheld & ~self._offset_beams).any():
            return scan
        ranges = masked.ranges_m.copy()
        ranges[self._offset_beams] = scan.ranges_m[self._offset_beams]
        return replace(masked, ranges_m=ranges)

    def _tight_confirmed(self, aligned_xytheta: np.ndarray) -> np.ndarray | None:
        """``aligned_xytheta`` (3,), the pose the alignment just gave back, if it confirmed
        the pose it was handed with at least ``publish_min_tight_fraction`` of its points
        within ``align_tight_m`` of a map edge (a pose to publish); else None."""
        a = self._aligner
        if (a.last_outcome != "confirmed"
                or a.last_tight_fraction < self.fusion.publish_min_tight_fraction):
            return None
        return np.array(aligned_xytheta, dtype=float)

    def _aligned_pose(self, loc_pose: np.ndarray, odom: np.ndarray,
                      confirmed: np.ndarray | None) -> np.ndarray:
        """``publish_pose: aligned``: ``confirmed`` (the alignment's pose on this scan, or
        None), else the last one carried by odometry while within ``publish_carry_*`` and
        ``max_offset_jump_m`` of the filter's ``loc_pose``, else ``loc_pose``. ``odom`` (3,):
        the carrying odometry's pose (:meth:`_carry_pose`: the wheels', or with
        ``carry_matcher_inflation`` theirs and the matcher's steps together)."""
        f = self.fusion
        if confirmed is not None:
            self._published_anchor = (_wrapped(confirmed), odom.copy(),
                                      f.publish_blend_base_std_m)
            return self._published_anchor[0]
        if self._published_anchor is None or self._settle_left_m > 0.0:
            self._published_anchor = None  # none yet, or the filter jumped since
            return loc_pose
        a_pose, a_odom, a_std_m = self._published_anchor
        d = relative(a_odom, odom)
        moved_m = float(np.hypot(d[0], d[1]))  # from where it was confirmed, not the path
        if f.publish_blend:
            beyond = moved_m > f.publish_blend_max_m
        else:
            beyond = moved_m > f.publish_carry_m or abs(d[2]) > np.radians(f.publish_carry_deg)
        if beyond:
            self._published_anchor = None
            return loc_pose
        carried = compose(a_pose, d)
        if np.hypot(*(carried[:2] - loc_pose[:2])) > f.max_offset_jump_m:
            return loc_pose
        if not f.publish_blend:
            return carried  # compose() wraps the heading
        suspect = self._last_align_outcome in SUSPECT_OUTCOMES
        return blend_poses(carried, loc_pose,
                           a_std_m + f.publish_blend_odom_std_per_m * moved_m,
                           f.publish_blend_suspect_std_m if suspect
                           else f.publish_blend_filter_std_m)

    def end_run(self) -> list:
        """Close a log: GATMO adds dominant chairs in Gamma to the map (paper, Sec. V)."""
        if self.mapper is None:
            return []
        events = list(self.mapper.end_run())
        self._apply_map_changes()
        self._aligner = None  # rebuilt from the new map on first use
        self._reloc_stale = True
        self._edges = None
        return events

    def current_grid(self, base: OccupancyGrid) -> OccupancyGrid:
        """The map the localizer is using now (the reconfigured map with GATMO, else ``base``)."""
        if self.loc_grid is not None:
            return self.loc_grid
        return self.mapper.grid() if self.mapper is not None else base
