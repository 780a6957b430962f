"""Load ROS 1 AMCL and Nav2 AMCL parameter YAML into :class:`AmclConfig`.

ROS 1 (flat, ``amcl`` node's private parameters) files get ROS 1 defaults; Nav2 files
(``amcl: ros__parameters: ...``) get Nav2 defaults. Parameters that only matter to a running
ROS graph (frames, topics, tf, rates) are accepted and reported as ignored. Unknown keys and
bad values are refused with the key's name, file and line.
"""

from __future__ import annotations

from pathlib import Path

from pydantic import ValidationError

from gatmo.config import read_yaml, validation_to_config_error, yaml_key_lines
from gatmo.errors import ConfigError
from gatmo.localization.config import AmclConfig

# ROS key -> gatmo field (shared by ROS 1 and Nav2 unless overridden)
COMMON = {
    "min_particles": "min_particles",
    "max_particles": "max_particles",
    "kld_err": "kld_err",
    "kld_z": "kld_z",
    "pf_err": "kld_err",
    "pf_z": "kld_z",
    "update_min_d": "update_min_d_m",
    "update_min_a": "update_min_a_rad",
    "resample_interval": "resample_interval",
    "recovery_alpha_slow": "recovery_alpha_slow",
    "recovery_alpha_fast": "recovery_alpha_fast",
    "selective_resampling": "selective_resampling",
    "do_beamskip": "do_beamskip",
    "beam_skip_distance": "beam_skip_distance_m",
    "beam_skip_threshold": "beam_skip_threshold",
    "beam_skip_error_threshold": "beam_skip_error_threshold",
    "global_localization_on_start": "global_localization_on_start",
}
ROS1 = {
    "laser_model_type": "laser_model",
    "laser_z_hit": "z_hit",
    "laser_z_short": "z_short",
    "laser_z_max": "z_max",
    "laser_z_rand": "z_rand",
    "laser_sigma_hit": "sigma_hit_m",
    "laser_lambda_short": "lambda_short",
    "laser_likelihood_max_dist": "laser_likelihood_max_dist_m",
    "laser_min_range": "laser_min_range_m",
    "laser_max_range": "laser_max_range_m",
    "laser_max_beams": "max_beams",
    "odom_model_type": "odom_model",
    "odom_alpha1": "alpha1",
    "odom_alpha2": "alpha2",
    "odom_alpha3": "alpha3",
    "odom_alpha4": "alpha4",
    "odom_alpha5": "alpha5",
    "initial_cov_xx": "initial_cov_xx_m2",
    "initial_cov_yy": "initial_cov_yy_m2",
    "initial_cov_aa": "initial_cov_aa_rad2",
}
NAV2 = {
    "laser_model_type": "laser_model",
    "z_hit": "z_hit",
    "z_short": "z_short",
    "z_max": "z_max",
    "z_rand": "z_rand",
    "sigma_hit": "sigma_hit_m",
    "lambda_short": "lambda_short",
    "laser_likelihood_max_dist": "laser_likelihood_max_dist_m",
    "laser_min_range": "laser_min_range_m",
    "laser_max_range": "laser_max_range_m",
    "max_beams": "max_beams",
    "robot_model_type": "odom_model",
    "alpha1": "alpha1",
    "alpha2": "alpha2",
    "alpha3": "alpha3",
    "alpha4": "alpha4",
    "alpha5": "alpha5",
}
IGNORED = {
    "base_frame_id", "odom_frame_id", "global_frame_id", "scan_topic", "map_topic",
    "tf_broadcast", "transform_tolerance", "save_pose_rate", "gui_publish_rate",
    "use_map_topic", "first_map_only", "bond_disable_heartbeat_timeout", "use_sim_time",
    "always_reset_initial_pose", "set_initial_pose", "initial_pose", "initial_pose_x",
    "initial_pose_y", "initial_pose_a", "receive_map_topic", "laser_model", "restore_defaults",
    "service_introspection_mode", "introspection_mode", "map_frame_id",
}
ROS1_DEFAULTS = {
    "min_particles": 100, "max_particles": 5000, "kld_err": 0.01, "kld_z": 0.99,
    "update_min_d_m": 0.2, "update_min_a_rad": 3.141592653589793 / 6.0, "resample_interval": 2,
    "recovery_alpha_slow": 0.001, "recovery_alpha_fast": 0.1, "max_beams": 30,
    "odom_model": "diff", "z_hit": 0.95, "z_short": 0.1, "z_max": 0.05, "z_rand": 0.05,
    "sigma_hit_m": 0.2, "laser_likelihood_max_dist_m": 2.0,
}
NAV2_ROBOT_MODELS = {
    "nav2_amcl::DifferentialMotionModel": "diff-corrected",
    "nav2_amcl::OmniMotionModel": "omni-corrected",
    "differential": "diff-corrected",
    "omnidirectional": "omni-corrected",
}


def _amcl_section(data: dict) -> tuple[object, tuple, bool]:
    """(the AMCL parameters, the keys leading to them, whether the layout is Nav2's) of a
    parsed AMCL YAML: flat (ROS 1), under ``amcl:`` and/or ``ros__parameters:`` (Nav2)."""
    prefix: tuple = ()
    nav2 = False
    if "amcl" in data and isinstance(data["amcl"], dict):
        data = data["amcl"]
        prefix = ("amcl",)
    if "ros__parameters" in data:
        data = data["ros__parameters"] or {}
        prefix += ("ros__parameters",)
        nav2 = True
    return data, prefix, nav2


def load_amcl_yaml(path: str | Path) -> AmclConfig:
    """Read a ROS 1 or Nav2 AMCL YAML into an :class:`AmclConfig`."""
    path = Path(path)
    data, text = read_yaml(path)
    lines = yaml_key_lines(text)
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError("expected a mapping of AMCL parameters", file=path)
    data, prefix, nav2 = _amcl_section(data)
    if not isinstance(data, dict):
        raise ConfigError("expected a mapping of AMCL parameters", file=path)
    table = dict(COMMON, **(NAV2 if nav2 else ROS1))
    values: dict = {} if nav2 else dict(ROS1_DEFAULTS)
    key_names = {}
    ignored: list[str] = []  # accepted, no effect offline
    for key, value in data.items():
        if key in table:
            field = table[key]
            key_names[field] = key
            if field == "odom_model" and nav2:
                if value not in NAV2_ROBOT_MODELS:
                    raise ConfigError(
                        f"unknown robot_model_type {value!r}: {' | '.join(NAV2_ROBOT_MODELS)}",
                        file=path, line=lines.get(prefix + (key,)), field=key)
                value = NAV2_ROBOT_MODELS[value]
            if field in ("laser_min_range_m", "laser_max_range_m") and isinstance(
                value, int | float
            ) and value < 0:
                value = None  # AMCL's -1.0: use the scan's own limit
            values[field] = value
        elif key in IGNORED:
            ignored.append(key)
        else:
            raise ConfigError("unknown AMCL parameter", file=path,
                              line=lines.get(prefix + (key,)), field=key)
    if nav2 and isinstance(data.get("initial_pose"), dict) and data.get("set_initial_pose"):
        ip = data["initial_pose"]
        values["initial_pose_xytheta"] = (ip.get("x", 0.0), ip.get("y", 0.0), ip.get("yaw", 0.0))
    if not nav2 and "initial_pose_x" in data:
        values["initial_pose_xytheta"] = (data.get("initial_pose_x", 0.0),
                                          data.get("initial_pose_y", 0.0),
                                          data.get("initial_pose_a", 0.0))
    try:
        cfg = AmclConfig.model_validate(values)
    except ValidationError as exc:
        raise validation_to_config_error(exc, file=path, lines=lines, prefix=prefix,
                                         key_names=key_names) from None
    return cfg


def amcl_yaml_dialect(path: str | Path) -> str:
    """``"nav2"`` when the AMCL YAML at ``path`` holds ``ros__parameters``, else ``"ros1"``."""
    data, _ = read_yaml(Path(path))
    return "nav2" if isinstance(data, dict) and _amcl_section(data)[2] else "ros1"


def amcl_yaml_text(values: dict, dialect: str = "nav2") -> str:
    """AMCL parameter YAML (``"nav2"``: ``amcl: ros__parameters:``, ``"ros1"``: flat) holding
    ``values``, a mapping of :class:`AmclConfig` field -> value; :func:`load_amcl_yaml` reads it
    back. Nav2 has no ROS 1 ``diff`` / ``omni`` (variance-as-std) models: refused."""
    import yaml

    table = dict(COMMON, **(NAV2 if dialect == "nav2" else ROS1))
    key_of = {}
    for key, fld in table.items():
        key_of.setdefault(fld, key)  # the first ROS name of a field (pf_err after kld_err)
    out = {}
    for fld, value in values.items():
        if fld not in key_of:
            raise ConfigError(f"no {dialect} AMCL parameter for {fld!r}", field=fld)
        if fld == "odom_model" and dialect == "nav2":
            names = {v: k for k, v in reversed(NAV2_ROBOT_MODELS.items())}
            if value not in names:
                raise ConfigError(f"Nav2 has no {value!r} odometry model (ROS 1 only)",
                                  field="robot_model_type")
            value = names[value]
        out[key_of[fld]] = value
    doc = {"amcl": {"ros__parameters": out}} if dialect == "nav2" else out
    return yaml.safe_dump(doc, sort_keys=False)
