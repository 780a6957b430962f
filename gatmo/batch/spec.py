"""SPEC.yaml for ``gatmo batch``: maps, log globs, a command, a parameter grid and seeds,
expanded into a list of :class:`Job` grouped into dependency chains.

A job is a pure function of (command, map, log(s), parameter point, seed); its id is a stable
hash of those inputs - the map's YAML and image bytes, the params file's bytes, each log's path,
size and modification time, the point, the seed and ``max_scans`` - so a checkpoint stops
counting once any of them changes. Its folder is readable:
``<command>/<site-or-log-stem>/<param-hash>/seed<k>`` (jobs of one log under a ``site`` add
``/<log-stem>``, so that the runs of a site sit side by side).
"""

from __future__ import annotations

import glob as _glob
import hashlib
import itertools
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from pydantic import Field, ValidationError

from gatmo.config import GatmoModel, load_model, read_yaml, yaml_key_lines
from gatmo.errors import ConfigError

COMMANDS = ("localize", "run", "compare", "echo")


class LogSpec(GatmoModel):
    """``map``: a name from ``maps``; ``glob``: log files (relative to the spec's folder);
    ``site``: optional chain name - ``run`` jobs of one site chain their object maps."""

    map: str
    glob: str
    site: str | None = None


class BatchSpec(GatmoModel):
    """The batch description. ``command`` ``echo`` is a test aid: it counts the log's lines,
    records the parameter point, raises when ``echo.fail`` is true and sleeps ``echo.sleep_s``."""

    maps: dict[str, str]
    logs: list[LogSpec] = Field(min_length=1)
    command: Literal["localize", "run", "compare", "echo"]
    params: str | None = None
    # a named stack configuration the points start from (gatmo.pipeline.config.STACK_PRESETS)
    # instead of the defaults; ``params`` still replaces its amcl section
    preset: str | None = None
    grid: dict[str, list[Any]] = Field(default_factory=dict)
    seeds: list[int] = Field(default_factory=lambda: [0], min_length=1)
    max_scans: int | None = Field(default=None, gt=0)


@dataclass(frozen=True)
class Job:
    """One unit of work. Paths are absolute strings; ``point`` is ((dotted key, value), ...)."""

    id: str
    command: str
    map_name: str
    map_yaml: str
    logs: tuple[str, ...]
    site: str | None
    params_path: str | None
    point: tuple[tuple[str, Any], ...]
    point_hash: str
    seed: int
    max_scans: int | None
    folder: str  # relative to the batch output folder
    chain_pos: int = 0  # position in its chain (0 = first / unchained)
    preset: str | None = None  # the named stack configuration the point starts from

    @property
    def log(self) -> str:
        return self.logs[0]


def _hash(obj: Any, n: int = 12) -> str:
    text = json.dumps(obj, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:n]


def apply_overrides(cfg, point, *, file=None, lines=None) -> None:
    """Set dotted ``point`` keys on a (nested) pydantic config, validating each assignment.

    A key that does not exist or a value of the wrong type raises ConfigError naming
    ``grid.<key>`` and the spec line."""
    for key, value in point:
        line = (lines or {}).get(("grid", key))
        parts = key.split(".")
        obj = cfg
        try:
            for p in parts[:-1]:
                if p not in type(obj).model_fields:
                    raise AttributeError(p)
                obj = getattr(obj, p)
            if parts[-1] not in type(obj).model_fields:
                raise AttributeError(parts[-1])
            setattr(obj, parts[-1], value)
        except AttributeError:
            raise ConfigError("unknown parameter", file=file, line=line,
                              field=f"grid.{key}") from None
        except ValidationError as exc:
            msg = exc.errors()[0].get("msg", "invalid value")
            raise ConfigError(f"{msg} (got {value!r})", file=file, line=line,
                              field=f"grid.{key}") from None


def load_spec(spec_path: str | Path) -> tuple[BatchSpec, Path]:
    """Load and validate SPEC.yaml; return (spec, spec folder)."""
    spec_path = Path(spec_path)
    return load_model(BatchSpec, spec_path), spec_path.resolve().parent


def expand_jobs(spec_path: str | Path) -> list[list[Job]]:
    """Expand a spec into chains of jobs (a chain of one for independent jobs).

    Grid: cartesian product of the value lists (keys in spec order). Each ``logs`` entry's glob
    is sorted by name; for ``run`` with a ``site`` those logs form a chain in that order (one
    chain per parameter point and seed). ``compare`` makes one job per ``logs`` entry with all
    its files. Unknown map names, globs matching nothing and bad grid keys raise ConfigError
    naming the key and line."""
    spec_path = Path(spec_path)
    spec, root = load_spec(spec_path)
    _, text = read_yaml(spec_path)
    lines = yaml_key_lines(text)

    def resolve(p: str) -> Path:
        q = Path(p).expanduser()
        return q if q.is_absolute() else (root / q)

    maps: dict[str, str] = {}
    for name, p in spec.maps.items():
        q = resolve(p)
        if not q.is_file():
            raise ConfigError(f"map not found: {q}", file=spec_path,
                              line=lines.get(("maps", name)), field=f"maps.{name}")
        maps[name] = str(q.resolve())
    params_path = None
    if spec.params is not None:
        q = resolve(spec.params)
        if not q.is_file():
            raise ConfigError(f"params file not found: {q}", file=spec_path,
                              line=lines.get(("params",)), field="params")
        params_path = str(q.resolve())

    if spec.preset is not None:
        from gatmo.pipeline.config import stack_preset

        try:
            stack_preset(spec.preset)
        except ConfigError as exc:  # the same message, with the spec's file and line
            raise ConfigError(exc.message, file=spec_path, line=lines.get(("preset",)),
                              field="preset") from None
    map_digest = {name: _map_digest(p) for name, p in maps.items()}
    params_digest = _digest([Path(params_path).read_bytes()]) if params_path else None

    keys = list(spec.grid)
    for k in keys:
        if not spec.grid[k]:
            raise ConfigError("empty list of values", file=spec_path,
                              line=lines.get(("grid", k)), field=f"grid.{k}")
    points = [tuple(zip(keys, vals, strict=True))
              for vals in itertools.product(*(spec.grid[k] for k in keys))]
    _check_points(spec, points, params_path, spec_path, lines, spec.preset)

    chains: list[list[Job]] = []
    for i, entry in enumerate(spec.logs):
        if entry.map not in maps:
            raise ConfigError(f"unknown map name {entry.map!r} (maps: {', '.join(maps)})",
                              file=spec_path, line=lines.get(("logs", i, "map")),
                              field=f"logs.{i}.map")
        pattern = str(resolve(entry.glob))
        files = sorted(str(Path(f).resolve()) for f in _glob.glob(pattern, recursive=True)
                       if Path(f).is_file())
        if not files:
            raise ConfigError(f"glob matches no file: {pattern}", file=spec_path,
                              line=lines.get(("logs", i, "glob")), field=f"logs.{i}.glob")
        for point in points:
            ph = _hash([list(p) for p in point], 8)
            for seed in spec.seeds:
                def job(logs, label, pos=0, sub=None, prev=None, _point=point, _ph=ph,
                        _seed=seed, _entry=entry):
                    # a chained run's input includes its predecessor (whose objects it reads)
                    jid = _hash([spec.command, maps[_entry.map], map_digest[_entry.map],
                                 [[lg, *_stat(lg)] for lg in logs],
                                 [list(p) for p in _point], _seed, spec.max_scans,
                                 params_path, params_digest, prev]
                                + ([spec.preset] if spec.preset is not None else []))
                    folder = f"{spec.command}/{label}/{_ph}/seed{_seed}"
                    if sub is not None:
                        folder += f"/{sub}"
                    return Job(jid, spec.command, _entry.map, maps[_entry.map], tuple(logs),
                               _entry.site, params_path, _point, _ph, _seed, spec.max_scans,
                               folder, pos, spec.preset)

                if spec.command == "compare":
                    chains.append([job(files, entry.site or entry.map)])
                elif entry.site is not None and spec.command in ("run", "echo"):
                    chain: list[Job] = []
                    for k, f in enumerate(files):
                        chain.append(job([f], entry.site, k, Path(f).stem,
                                         chain[-1].id if chain else None))
                    chains.append(chain)
                else:
                    for f in files:
                        if entry.site is not None:  # several logs per site: one folder each
                            chains.append([job([f], entry.site, sub=Path(f).stem)])
                        else:
                            chains.append([job([f], Path(f).stem)])
    # the same job listed twice (overlapping globs) runs once
    unique: dict[tuple[str, ...], list[Job]] = {}
    for ch in chains:
        unique.setdefault(tuple(j.id for j in ch), ch)
    chains = list(unique.values())
    seen: dict[str, str] = {}
    ids: set[str] = set()
    for ch in chains:
        for j in ch:
            if j.id in ids:  # overlapping site globs: one run inside two chains
                raise ConfigError(f"the job in {j.folder} belongs to two chains; give the "
                                  "logs entries of one site disjoint globs", file=spec_path,
                                  field="logs")
            ids.add(j.id)
            if j.folder in seen and seen[j.folder] != j.id:
                raise ConfigError(f"two jobs would share the folder {j.folder}; give the logs "
                                  "distinct sites or names", file=spec_path, field="logs")
            seen[j.folder] = j.id
    return chains


def _digest(blobs) -> str:
    h = hashlib.sha256()
    for b in blobs:
        h.update(hashlib.sha256(b).digest())
    return h.hexdigest()[:16]


def _map_digest(map_yaml: str) -> str:
    """Hash of the map's files (YAML and image) as shipped to workers."""
    from gatmo.batch.jobs import map_bundle

    files = map_bundle(map_yaml)["files"]
    return _digest(files[k] for k in sorted(files))


def _stat(path: str) -> list[int]:
    """A log's identity beyond its path without reading it (logs can be large)."""
    st = Path(path).stat()
    return [st.st_size, st.st_mtime_ns]


def _check_points(spec, points, params_path, spec_path, lines, preset=None) -> None:
    if spec.command == "echo":
        for k in spec.grid:
            if not k.startswith("echo."):
                raise ConfigError("echo jobs take only echo.* keys", file=spec_path,
                                  line=lines.get(("grid", k)), field=f"grid.{k}")
        return
    for point in points:  # every value is validated before any job starts
        cfg = base_stack_config(params_path, preset)
        apply_overrides(cfg, point, file=spec_path, lines=lines)


def base_stack_config(params_path: str | None, preset: str | None = None):
    """The stack config every point starts from: the defaults (or the named ``preset``), the
    AMCL section from ``params``."""
    from gatmo.pipeline.config import load_stack_config

    return load_stack_config(None, params_path, preset)


__all__ = ["BatchSpec", "Job", "LogSpec", "apply_overrides", "expand_jobs", "load_spec"]
