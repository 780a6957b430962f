"""``--set key=value`` config overrides shared by the benchmark scripts."""

from __future__ import annotations


def add_override_args(ap) -> None:
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="stack config override, dotted key and YAML value, e.g. "
                    "fusion.align_to_map=false (repeatable)")
    ap.add_argument("--sim-set", action="append", default=[], metavar="KEY=VALUE",
                    help="simulator config override, e.g. laser.max_range_m=8 (repeatable; "
                    "the world before anything moved gets it too)")
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
