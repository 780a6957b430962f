"""GATMO's parameters, with the paper's names where it has them (Gallagher et al., ICRA 2009)."""

from __future__ import annotations

from typing import Any, ClassVar

from pydantic import Field

from gatmo.config import GatmoModel


class GatmoConfig(GatmoModel):
    """Object map, absence, metaobjects and matching.

    Paper names: ``delta_R_m`` (grid side for the person likelihood integral, eq. P(x|p)),
    ``delta_W_m`` (width of the neighbourhood N_i around an object's edges), ``beta_thresh``
    (fraction of an object's cells seen through before it is absent, Alg. 1), ``tau_memory_s``
    (a metaobject unseen this long is discarded), ``beta_min_prob`` (per-point probability of
    the new-object hypothesis m_new).
    """

    # built, measured as no better than the defaults and left off, then removed (forty-second
    # session, docs/experiments.md); a file naming one at its old default still loads
    removed_options: ClassVar[dict[str, Any]] = {
        "no_return_hits": False, "track_from_verified_only": False, "chair_align_cells": 0,
        "match_shift_unseen": False, "match_ambiguity_rivals": "unseen",
        "match_ambiguous_min_score": None, "match_settle_min_edge_fraction": 0.3,
        "match_free_from": "run", "match_min_verified_scans": 0,
        "match_from_verified_grid": False, "gamma_split_gap_m": None,
        "match_gamma_to_absent": False, "match_gamma_strict": False,
        "part_ring_connected": False, "part_ring_min_cells": 3, "match_gamma_part_check": False,
        "match_extent_record": False, "match_rank_extent": False,
        "match_absence_reclaims": False, "match_gamma_beam_check": False,
        # read by nothing since the chair / person verdict stopped using the Kalman filter's
        # speed and the coarse search turned by a fixed +-6 deg (forty-sixth session)
        "chair_max_speed_mps": 0.15, "match_search_deg": 12.0,
        # an absence not matched to a Gamma object seen before the object last stood where
        # the map has it: ACES lost (forty-sixth session)
        "match_gamma_after_standing": False, "standing_min_beams": 4}

    delta_R_m: float = Field(
        0.05, gt=0, description="the paper's delta_R: the person hypothesis integrates its "
        "Kalman filter's normal over a square of side 2 delta_R around each return (P(x_k|p_j)). "
        "The paper's grid side; the grids here take the map's resolution")
    delta_W_m: float = Field(
        0.15, gt=0, description="the paper's delta_W (the neighbourhood N_i): returns within "
        "this of an occupied map cell are explained by the map (S_free) and not tracked; also "
        "how near a chair's cells must lie to a Gamma object to be the same one")
    beta_thresh: float = Field(
        0.6, gt=0, lt=1, description="the paper's beta_thresh (Alg. 1): an object is marked "
        "absent when more than this fraction of its core cells was seen through this run (or "
        "of the surface cells beams should have ended on was passed), and absence_min_rays, "
        "absence_min_beams and absence_through_fraction are met")
    tau_memory_s: float = Field(
        4.0, gt=0, description="the paper's tau_memory: a metaobject not seen for longer than "
        "this is discarded; an unmatched chair then joins Gamma")
    beta_min_prob: float = Field(
        0.02, gt=0, lt=1, description="the paper's beta_min_prob: the probability per point "
        "of the new-object hypothesis m_new; a cluster no metaobject explains better starts a "
        "new one")
    # object map
    wall_min_extent_m: float = Field(2.5, gt=0, description="larger objects are structure")
    min_object_cells: int = Field(6, ge=1, description="smaller specks are structure")
    # absence (Alg. 1), made robust
    absence_exclude_end_m: float = Field(
        0.12, ge=0, description="cells within this of a ray's return are not counted as "
        "crossed by it (seen free, seen through, passed): a return on an object is not a ray "
        "through it")
    absence_min_rays: int = Field(
        20, ge=1, description="rays that must have crossed an object's cells this run before "
        "it may be marked absent")
    absence_max_range_m: float = Field(5.0, gt=0, description="rays and beams beyond: no evidence")
    absence_near_m: float = Field(0.35, gt=0,
                                  description="returns this near an object: it is there")
    absence_near_min_cells: int = Field(3, ge=1, description="cells with 2 returns near it")
    absence_margin_m: float = Field(0.15, ge=0, description="count only cells this far inside")
    absence_beyond_m: float = Field(0.4, gt=0, description="a return this far beyond = gone")
    hit_tolerance_m: float = Field(0.15, gt=0, description="a return this near = there")
    absence_max_incidence_deg: float = Field(
        90.0, gt=0, le=90, description="beyond the paper: a beam meeting the map's surface "
        "more than this angle from its normal (grazing it, or running along a thin thing "
        "end-on) is no evidence that an object is gone or there (nor counts in the scan's "
        "agreement with the map): a map built from scans has "
        "such a surface a cell or two off, and a beam along a bench 2 cells thick passes its "
        "cells while the bench stands (ACES; docs/experiments.md, forty-fifth session). 90: "
        "every beam counts (the paper)")
    absence_far_hits: bool = Field(
        False, description="beyond the paper: beams ending on an object beyond "
        "absence_max_range_m count against its absence (as beams ending on it nearer do), "
        "though beams passing it there still do not count for it. Region growing joins a "
        "wall's corner and a thing that stood beside it when the map was made; the beams "
        "passing the near part where the thing has gone then sent the whole corner absent, "
        "while the beams ending on its far part went uncounted (ACES; docs/experiments.md, "
        "forty-fifth session). A heading error moves a far beam along a surface, but one "
        "ending on the object still says something stands there")
    absence_min_beams: int = Field(8, ge=1, description="beams through it before absent")
    absence_through_fraction: float = Field(0.75, gt=0, le=1,
                                            description="of beams through or on it, through")
    doubt_min_beams: int = Field(4, ge=1, description="beams through it before in doubt")
    doubt_fraction: float = Field(
        0.2, gt=0, le=1, description="of the beams passing or ending on an object this run, "
        "the fraction passing through that puts it in doubt (with doubt_min_beams): returns "
        "near it are then no longer explained by the map, so a track can show where it is now")
    doubt_search_m: float = Field(1.5, gt=0, description="how far a doubted object may shift")
    confirm_min_beams: int = Field(10, ge=1, description="beams on a movable object: it is there")
    min_agreement: float = Field(0.75, ge=0, le=1,
                                 description="of beams the map expects a hit for, on it")
    absence_min_agreement: float = Field(0.85, ge=0, le=1,
                                         description="stricter min_agreement for absence")
    absence_from_verified_only: bool = Field(
        True, description="rays seen through objects count only from poses an independent "
        "check confirmed (pose_verified); other poses' returns still show objects there")
    agreement_gone_min_beams: int = Field(
        3, ge=1, description="an object this scan sees through with at least this many beams")
    agreement_gone_fraction: float = Field(
        0.7, gt=0, le=1, description="and this fraction of its beams is left out of the "
        "agreement: it was moved, the pose is not wrong")
    agreement_gone_max_share: float = Field(
        0.5, ge=0, le=1, description="of the objects in view, at most this many (or one) may be "
        "left out; more gone at once means a wrong pose")
    agreement_min_beams: int = Field(20, ge=1, description="fewer: the scan is skipped")
    agreement_structure_min_beams: int | None = Field(
        None, ge=1, description="beyond the paper: more objects in view seen through as a "
        "whole than agreement_gone_max_share allows are still left out of the pose test when "
        "at least this many of the beams the map expects to end on structure (walls, columns) "
        "end there, min_agreement of those that reach it: a wrong pose disagrees on the walls "
        "too, a room where two pieces in view were moved does not (tuning hall 303 run 3: a "
        "shifted cabinet and a moved piece seen through together, 25-28 wall beams all "
        "agreeing, GATMO skipping every scan near the cabinet's new place). Walls of one "
        "direction fit a pose slid along them too; its rays count as evidence of absence only "
        "if the scan-to-map alignment confirmed it (absence_from_verified_only). At 20 "
        "(fifty-first session): over 50 held-out (seed, filter draw) rows of halls 400-419 "
        "and 100-109 found +0.9 points [+0.1, +2.0], false relocations +0.04 per seed "
        "[-0.11, +0.18] (+0.25 on 400-419 draw 0), ATE the same; offices and real logs the "
        "same; but the demo 0.173 -> 0.233 m (run 4's straight lost 14.8 % of the time): left "
        "off. None: the plain test decides")
    unexplained_sparse_min_beams: int | None = Field(
        None, ge=1, description="beyond the paper: a scan skipped for too few beams the map "
        "expects to end on something (fewer than agreement_min_beams, at least this many) whose "
        "expected beams agree (min_agreement) still counts its unexplained returns for the "
        "localizer's mask (fusion.mask_unexplained), and is no other evidence: in a sparse view "
        "a piece moved since the map was made pulls the filter onto its old place (hall seed "
        "403 run 3, replayed: ATE 0.30 -> 0.17 m). None (the default): such scans count "
        "nothing. At 5, halls 400-419 ATE 0.117 -> 0.168 m (two seeds lost that were not) and "
        "0.151 -> 0.142 m with filter draw 10 (lower on 14 of 20), 100-109 0.102 -> 0.101 m "
        "and 0.129 -> 0.121 m (draw 10), with 0.2-0.3 more false relocations per seed: no "
        "better than the filter's chaos "
        "(docs/experiments.md, forty-first session)")
    min_explained_fraction: float = Field(0.3, ge=0, le=1,
                                          description="returns the map explains, else skip")
    # unexplained returns
    meanshift_bandwidth_m: float = Field(
        0.35, gt=0, description="radius of the flat mean shift kernel that splits a scan's "
        "unexplained returns into clusters; modes closer than half of it are merged")
    min_cluster_points: int = Field(
        3, ge=1, description="returns a cluster needs to be tracked; a scan with fewer "
        "unexplained returns is not clustered")
    gate_m: float = Field(
        1.0, gt=0, description="a cluster is compared only with metaobjects whose Kalman "
        "centre lies within this of its mean, or whose evidence cells lie within a third of it "
        "of one of its returns")
    track_max_range_m: float = Field(5.0, gt=0,
                                     description="farther returns are too sparse to track")
    track_range_margin_m: float = Field(
        0.7, ge=0, description="returns within this of the laser's max range are not tracked")
    match_max_move_m: float | None = Field(
        None, gt=0, description="beyond the paper: a match may move an object at most this far "
        "[m] from where it was (a site's prior: furniture is rearranged within a room); farther, "
        "the chair is refused and, if it stays, joins the map as a new object at the run's end, "
        "while the absent object keeps its identity and its old pose's history. None: no limit "
        "(the paper)")
    match_far_near_view_m: float = Field(
        3.3, gt=0, description="a match putting an object more than doubt_search_m from where "
        "it was needs a chair seen within this range [m] (the median range of its returns) "
        "in at least one scan: from farther, a beam every 6 cm or more and a degree of heading "
        "error smear the outline past telling look-alikes across the room apart. 3.3 m is "
        "how far a 4 m laser tracks (track_range_margin_m), so there it refuses nothing; with "
        "an 8 m laser it cuts the false relocations by a third (docs/experiments.md, "
        "forty-third session)")
    # person hypothesis (constant-velocity Kalman filter on the centre)
    person_accel_std: float = Field(
        1.5, gt=0, description="acceleration noise [m/s^2] of the person hypothesis's "
        "constant-velocity Kalman filter (its process noise)")
    person_meas_std_m: float = Field(
        0.1, gt=0, description="measurement noise of the person hypothesis's Kalman filter: "
        "the standard deviation of a cluster's centre as a measurement of the person's")
    # chair hypothesis (evidence grid)
    chair_min_scans: int = Field(
        9, ge=1, description="scans before a track can be a chair (be matched, join Gamma). At "
        "6, 19 of 45 wrong relocations with true poses (tuning seeds 300-309) came at the first "
        "try, a small piece onto part of a larger one seen from one side; at 9 (the paper: 10 "
        "to 70 scans to identify) false relocations per run fall 0.61 -> 0.40 (full stack, "
        "seeds 300-319) and 0.60 -> 0.45 (true poses, held-out seeds 100-109)")
    chair_min_cells: int = Field(
        6, ge=1, description="chair cells (Metaobject.chair_points: evidence cells hit in 2 "
        "scans or more) a track needs before it is matched, joins Gamma or becomes a "
        "provisional landmark")
    still_to_gamma: bool = Field(
        False, description="beyond the paper: a track called a person for its motion alone "
        "(its centre travelled) whose evidence is concentrated (still_min_concentration) joins "
        "Gamma when it ends, as a chair would, without being matched: two pieces side by side "
        "seen in turn from a moving robot, whose centre wanders farther than a piece's size")
    still_min_concentration: float = Field(
        0.9, gt=0, le=1, description="share of a track's evidence on cells hit in "
        "still_min_hits scans or more that makes it still")
    still_min_hits: int = Field(3, ge=2, description="hits that make a cell's evidence firm")
    still_max_vacated: float | None = Field(
        None, ge=0, le=1, description="beyond the paper: with a value, a track called a person "
        "for its motion only is still (still_to_gamma) when at most this share of its evidence "
        "lies on cells later scans saw through (Metaobject.vacated) and its concentration "
        "reaches still_vacated_min_concentration, instead of still_min_concentration. At the "
        "true poses of tuning halls 300-308 (36 runs): tracks on pieces 0.03 at most (165), "
        "off them 0.26 or more but 4 of 119. None (the concentration alone): at 0.2 the soak "
        "had one chain of four better and one worse, as with still_min_concentration 0.75, and "
        "halls 400-419 two seeds changed (docs/experiments.md, seventy-fourth session)")
    person_min_vacated: float | None = Field(
        None, ge=0, le=1, description="beyond the paper: with a value, a track of "
        "chair_min_scans scans or more with more than this share of its evidence on cells "
        "later scans saw through (Metaobject.vacated) is a person, however well its returns "
        "fit its chair grid (people walking slowly). Off: at 0.2 on hall seeds 400-419, twin "
        "swaps +0.35 per seed and noticed gone -1.4 points (with still_max_vacated 0.2) or -4 "
        "(nearly alone, one seed lost): the stack's pose error sees real chairs through too "
        "(docs/experiments.md, seventy-fourth session)")
    still_vacated_min_concentration: float = Field(
        0.6, ge=0, le=1, description="with still_max_vacated: the concentration "
        "(Metaobject.concentration) a track called a person for its motion needs to be still: "
        "a person walking straight at the laser hides the cells they left instead of leaving "
        "them to be seen through, and hits none of them again. Pieces seen in parts by a "
        "moving robot: 0.72 and more (soak chain 14)")
    # matching
    match_min_score: float = Field(
        0.75, gt=0, le=1, description="a match's edge score must reach this. 0.75 since "
        "2026-11-26 (thirteenth session), with the ambiguity wait, settle and provisional "
        "landmarks: over 50 held-out hall seeds, against 0.8 without them, found +2.5 points, "
        "false relocations -0.12 per run, ATE unchanged (docs/experiments.md). 0.8 "
        "re-measured with them (twenty-second session, tuning seeds 300-319): false "
        "relocations 1.15 -> 0.85 per seed, found 18.1 % -> 14.8 %, ATE 0.150 -> 0.285 m")
    match_patience_scans: int = Field(30, ge=1, description="after this, match despite doubt")
    absent_candidate_runs: int | None = Field(
        10, ge=1, description="beyond the paper, for a long life: an object absent for more "
        "than this many runs is no longer a candidate (nor a rival) for the chairs GATMO "
        "tracks; it stays in objects.json with its history. Every absent object is matched "
        "against every chair tracked, so without a bound the time per scan grows with the "
        "absences a robot's life piles up: 1000 absent objects made a hall run 8x slower, "
        "one scan 5.5 s (benchmarks/bench_gatmo_scaling.py, fifty-third session); the 50-run "
        "soak's figures stayed within its chains' spread. None: every absent object stays a "
        "candidate, as in the paper")
    match_unseen_movable: bool = Field(
        False, description="the paper's matching of chairs with movable objects whose place "
        "was not seen this run (after match_patience_scans); off: a piece not visited yet is "
        "taken by any look-alike chair (true poses, hall seeds 100-105: 2.2 false relocations "
        "per run with it, 1.75 without, and more pieces found)")
    prior_earlier_poses: bool = Field(
        True, description="every pose an object stood at keeps a prior: a chair that matches "
        "an object at one of its earlier poses is preferred over other candidates, and may "
        "relocate a movable object whose place was not seen this run (people put chairs back "
        "where they were)")
    earlier_pose_tolerance_m: float = Field(
        0.15, gt=0, description="a match this close (footprint distance) to an earlier pose "
        "is at that pose")
    match_beam_check: bool = Field(
        True, description="beyond the paper: the object placed at a match must not stand where "
        "beams of the scans that saw the chair went on well past it")
    match_through_m: float = Field(0.2, gt=0, description="a beam this far beyond: through")
    match_max_through_fraction: float = Field(
        0.1, ge=0, le=1, description="of the beams on the placed object or through it, through")
    match_min_edge_fraction: float = Field(
        0.3, ge=0, le=1, description="a chair is matched to an object only with at least this "
        "many chair cells per edge cell of the object: fewer is too little seen to tell "
        "look-alikes apart (the nudge asks as many)")
    match_ambiguity_wait: bool = Field(
        True, description="beyond the paper: a chair that fits a different-looking shape of "
        "the map (any object, candidate or not) nearly as well as its best match waits for "
        "more scans (up to match_ambiguity_patience_scans): a corner seen of a lounge chair "
        "fits a cabinet's corner")
    match_ambiguity_margin: float = Field(
        0.05, ge=0, le=1, description="a rival shape scoring within this of the best match "
        "makes the chair ambiguous")
    match_ambiguity_patience_scans: int = Field(
        30, ge=1, description="after this many scans of the chair, match despite ambiguity")
    match_ambiguity_settle: bool = Field(
        True, description="a chair whose match waited on ambiguity and that leaves (not seen "
        "for tau_memory, or the run ends) takes its best match then, as without the wait")
    match_free_first: bool = Field(
        True, description="beyond the paper: of the alignments a partial view allows, the best "
        "that covers no space seen free (else the best, then refused)")
    match_free_rays: int = Field(2, ge=1, description="rays through a cell to call it free")
    match_max_free_fraction: float = Field(
        0.05, ge=0, le=1, description="of the object's inner cells at a matched pose, the "
        "fraction that may lie where match_free_rays rays crossed this run; more: refused")
    match_edge_sigma_m: float = Field(
        0.05, gt=0, description="width (sigma) of the gaussian around each of an object's "
        "edge points in the field a match is scored on; the coarse search uses 2.5 times it")
    match_search_m: float = Field(
        0.4, gt=0, description="the coarse search of a match moves the object's centroid up "
        "to this plus half the object's size from the chair's centroid, in 0.1 m steps")
    small_object_area_m2: float = Field(
        0.045, ge=0, description="objects with less occupied area are small: matched only "
        "within doubt_search_m, absent only with no returns around them")
    match_twin_nearest: bool = Field(
        True, description="beyond the paper: of candidates for one chair in the same tier "
        "that look alike (lookalike_tolerance), the one nearest to where it was, unless the "
        "best scores more than match_twin_score_margin above it: between twins the edge "
        "score's difference is where the map's cells fell, not which piece it is")
    match_twin_score_margin: float = Field(
        0.05, ge=0, description="match_twin_nearest: a look-alike scoring at most this much "
        "below the best counts as scoring as well")
    lookalike_tolerance: float = Field(
        0.15, gt=0, description="two objects look alike when their cell counts and principal "
        "extents differ by at most this fraction: a moved object makes its look-alikes movable, "
        "and a look-alike is no rival that makes a match wait")
    add_min_cells: int = Field(
        10, ge=1, description="a Gamma object seen this run with fewer cells is not added to "
        "the map at the run's end")
    absence_looks_near: bool = Field(
        False, description="beyond the paper: before an object is marked absent, it is matched "
        "onto this run's returns around its outline (within nudge_max_shift_m, nearer to it "
        "than to anything else); a match that passes the nudge's tests relocates it there, "
        "keeping its id (a piece shifted by about its size: rays pass its old cells, and its "
        "returns are beside them)")
    absence_near_min_edge_fraction: float = Field(
        0.2, ge=0, le=1, description="absence_looks_near: the returns gathered must cover at "
        "least this fraction of the object's edge cells (and chair_min_cells)")
    nudge: bool = Field(
        True, description="beyond the paper: an object whose returns miss its outline while "
        "the rest of the scan fits the map (a piece shifted by less than its size) is matched "
        "onto those returns and relocated (GatmoMapper._nudge)")
    nudge_radius_m: float = Field(
        0.6, gt=0, description="returns this near an object, nearer to it than to anything "
        "else, are its own for the nudge")
    nudge_min_off_fraction: float = Field(
        0.3, gt=0, le=1, description="of an object's returns in a scan, the fraction more "
        "than offset_min_m off its outline for the scan to count against its place")
    nudge_min_scans: int = Field(5, ge=1, description="such scans before (and between) tries")
    nudge_min_cell_scans: int = Field(
        2, ge=1, description="a cell joins the returns the object is matched onto when hit "
        "in this many of those scans (people walking past are not)")
    nudge_min_gain: float = Field(
        0.15, ge=0, description="the match must score this much above the object's current "
        "pose")
    nudge_min_shift_m: float = Field(
        0.15, ge=0, description="a match whose footprint moves less (mean cell distance) is "
        "no shift: pose jitter of a few cm smears the returns by as much")
    nudge_max_shift_m: float = Field(1.0, gt=0, description="farther: not a shift")
    offset_min_returns: int = Field(
        4, ge=1, description="GatmoMapper.offset_at: returns an object needs in a scan before "
        "they can be said to miss it")
    offset_min_m: float = Field(
        0.08, gt=0, description="GatmoMapper.offset_at: median distance of an object's returns "
        "to it above which they miss it")
    offset_fit_m: float = Field(
        0.05, gt=0, description="GatmoMapper.offset_at: a return this close to the map fits it")
    offset_min_fit_fraction: float = Field(
        0.6, ge=0, le=1, description="GatmoMapper.offset_at: of the scan's other returns near "
        "the map, the fraction that must fit it (else the pose, not an object, is off)")
    provisional_landmarks: bool = Field(
        True, description="beyond the paper: while a run lasts, still chairs not (yet) "
        "matched to a map object (dominant chair tracks with provisional_min_verified_scans "
        "from confirmed poses, and this run's Gamma objects) go into the localizer's map as "
        "anonymous outlines (cells hit in 2 confirmed scans), and returns near them are no "
        "longer withheld as unexplained; GATMO's own map and the saved map do not change. A "
        "chair whose match waits (match_ambiguity_wait) or that joins Gamma still holds the "
        "filter where a wrong identity would have put the right outline")
    withhold_unseen_runs: int | None = Field(
        None, ge=1, description="beyond the paper: a placed movable object not seen standing "
        "in this many runs (MapObject.unseen_runs; seen standing: confirm_min_beams beams from "
        "confirmed poses ending on it and not in doubt, or placed by a match or an add) is left "
        "out of the localizer's map, so a piece that may have left long ago does not pull the "
        "filter; it stays in the object map, tested for absence as before, and goes back into "
        "the localizer's map on the scan that sees it standing. None: every placed object is "
        "in the localizer's map")
    end_run_take_unseen_runs: int | None = Field(
        None, ge=1, description="beyond the paper: a chair about to join the map at a run's "
        "end as a new object is instead the movable object that fits it best (match score, "
        "free space, extent) among those not seen standing at their place in this many runs, "
        "this one included; that object is relocated onto it and keeps its id. None: every "
        "such chair is a new object, and the unseen piece stays where it stood. At 2, soak "
        "chain 11 kept 5 stale objects after run 50 instead of 16 but made 10 false "
        "relocations in 50 runs instead of 4 (found 3 instead of 2); chain 14: 16 instead of "
        "21, false relocations 7 instead of 5; halls 400-419 false relocations +0.15 per seed "
        "(docs/experiments.md, seventy-fifth session): most pieces it would take are "
        "look-alikes, or pieces the map never had")
    withhold_agreement: bool = Field(
        True, description="with withhold_unseen_runs: the beams the map expects to end on a "
        "withheld object are left out of the test of a scan's pose (min_agreement), as they "
        "are out of the localizer's map; rays through them are still evidence of absence")
    provisional_min_verified_scans: int = Field(
        3, ge=1, description="scans of a track from confirmed poses before its outline is a "
        "provisional landmark")
    provisional_every_scans: int = Field(
        5, ge=1, description="GATMO updates between refreshes of the provisional landmarks")
    provisional_near_m: float = Field(
        0.15, gt=0, description="returns this close to a provisional landmark's cells are "
        "explained by it (no longer withheld from the localizer)")
    gamma_min_verified_scans: int = Field(
        1, ge=0, description="scans from independently confirmed poses a new object needs")
    match_absence_to_gamma: bool = Field(
        True, description="the paper's order-free matching, one way: an object found absent "
        "is matched to the Gamma objects seen this run (chairs whose tracks ended unmatched). "
        "Off (tuning seeds 300-319): false relocations unchanged, found 18.1 % -> 17.3 %")
    match_retake_from_gamma: bool = Field(
        True, description="beyond the paper: an object the absence's match put on a Gamma "
        "object stays, for the rest of the run, a candidate (as an absent one) for chairs "
        "within doubt_search_m (and its extent) of where it was absent from; taken back, the "
        "Gamma object joins the map at once (it had held the object in the localizer's map). "
        "Real logs with pieces moved in their maps: found 4 -> 10 of 36 (ACES 0 -> 5); ACES' "
        "unedited map ATE 0.078 -> 0.084 m; halls, offices, soak and the demo the same to "
        "the digit (fifty-fifth and fifty-sixth sessions)")
    match_retake_from_chair: bool = Field(
        True, description="beyond the paper: an object a track's chair took from A this "
        "run, farther than doubt_search_m (and its extent) from where it was absent, stays a "
        "candidate for chairs near that place for the rest of the run, as with "
        "match_retake_from_gamma; taken back, the track it leaves is an unmatched chair again "
        "(into Gamma if it has ended). Hall seed 400: found 2 -> 6 of 20, twin swaps 3 -> 1; "
        "hall 305 a twin swap fewer, a piece less noticed gone; the other 48 hall seeds, the "
        "offices, soak chains 11 and 14, the real moves and the demo the same to the digit "
        "(fifty-sixth session)")
    match_extent_check: bool = Field(
        False, description="beyond the paper: a chair whose returns in one scan reach past "
        "the object's sides (its cells' smallest rectangle) by more than "
        "match_extent_max_excess_m is not that object, on the tracks' and the Gamma objects' "
        "match paths (matching.extent_excess). One scan's returns are not smeared by the "
        "pose's error from scan to scan, so a 0.50 m box seen end to end reaches past a "
        "0.45 m footstool's outline, which the blurred edge score cannot tell. On in "
        "sim_stack_config: the threshold hangs on how the map was drawn")
    match_extent_max_excess_m: float = Field(
        0.02, ge=-0.2, le=0.5, description="how far a chair's sides, one scan at a time, may "
        "reach past the object's cells' smallest rectangle [m]. Set on the simulator's maps, "
        "which occupy every cell a piece overlaps: along a turned piece's sides their "
        "centres reach 3.5-4.6 cm past it on average. A map that marks the cell each return "
        "lands in, or each cell whose centre is inside, has centres up to a cell short of "
        "a side's ends (a piece square to the grid): there about a cell more is needed")
    add_max_passed_fraction: float = Field(
        0.5, ge=0, le=1, description="of a new object's cells, the fraction rays may have "
        "passed (match_free_rays of them, going on add_gone_beyond_m or more) since a return "
        "last landed there: above it, it has gone again this run and is not added")
    add_max_flicker: float = Field(
        0.6, ge=0, le=1, description="of the beams that reached a new object's cells this "
        "run after a return first landed there, the fraction that may have passed well "
        "beyond them (median over the cells returns landed in): above it, it came and went "
        "(people, a door) and is not added; 1: no test. Things added in simulated halls: 0-0.18; "
        "on the Intel log a chair there at the last two visits 0.41, two things gone on most "
        "visits 0.86")
    add_gone_beyond_m: float = Field(
        0.25, gt=0, description="a ray counts as passing a cell for add_max_passed_fraction "
        "only if it ends this far beyond it")
    add_gone_max_range_m: float = Field(
        8.0, gt=0, description="rays count as passing a new object's cells for "
        "add_max_passed_fraction up to this range, beyond absence_max_range_m: not adding a "
        "thing is a milder error than marking one absent, and a robot often sees last, from "
        "across the room, that a thing has gone again (on the Intel log mostly from 5-9 m)")
    add_gone_min_agreement: float = Field(
        0.7, ge=0, le=1, description="a scan whose pose agrees with the map on fewer beams "
        "than absence_min_agreement still counts for add_max_passed_fraction from this on")
    add_min_free_fraction: float = Field(
        0.5, ge=0, le=1, description="of a new object's cells, free in the static map")
