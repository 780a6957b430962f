"""``--set key=value`` config overrides shared by the benchmark scripts."""

from __future__ import annotations


def add_override_args(ap, static: bool = False) -> None:
    """``--set``, ``--sim-set``, ``--tag``; with ``static``, ``--static-set`` too."""
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="stack config override, dotted key and YAML value, e.g. "
                    "fusion.align_to_map=false (repeatable)")
    ap.add_argument("--sim-set", action="append", default=[], metavar="KEY=VALUE",
                    help="simulator config override, e.g. laser.max_range_m=8 (repeatable; "
                    "the world before anything moved gets it too)")
    if static:
        ap.add_argument("--static-set", action="append", default=[], metavar="amcl.KEY=VALUE",
                        help="the static side's localizer only, on top of --set, e.g. "
                        "amcl.laser_model=likelihood_field (repeatable): a peer configured "
                        "as AMCL users run it, in the same run")
    ap.add_argument("--tag", default="", help="suffix of the output names")


def with_overrides(cfg, overrides: list[str] | None):
    """``cfg`` (a StackConfig, or a SimConfig for ``--sim-set``) with ``key=value`` overrides
    applied, validated; returned."""
    import yaml

    from gatmo.batch.spec import apply_overrides

    pairs = []
    for kv in overrides or []:
        key, _, value = kv.partition("=")
        pairs.append((key.strip(), yaml.safe_load(value)))
    apply_overrides(cfg, pairs)
    return cfg


def static_amcl(cfg, overrides: list[str] | None):
    """The static side's ``amcl`` section: a copy of ``cfg.amcl`` (``cfg`` a StackConfig) with
    ``amcl.KEY=VALUE`` overrides, validated; None without overrides (the static side runs the
    stack's own). A key outside ``amcl.`` is a ConfigError: the static side has no other."""
    from gatmo.errors import ConfigError

    if not overrides:
        return None
    for kv in overrides:
        if not kv.strip().startswith("amcl."):
            raise ConfigError(f"--static-set {kv!r}: only amcl.* keys apply to the static side",
                              field="--static-set")
    return with_overrides(cfg.model_copy(deep=True), overrides).amcl
