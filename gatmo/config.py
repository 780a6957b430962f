"""Validated configuration models (pydantic) and YAML loading with located errors.

Each component defines one model deriving from :class:`GatmoModel`; unknown keys are refused by
name, wrong types and out-of-range values by key. :func:`load_model` turns a YAML file into a
model and any problem into a :class:`~gatmo.errors.ConfigError` naming file, line and key.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, ClassVar, TypeVar

import yaml
from pydantic import BaseModel, ConfigDict, ValidationError, model_validator

from gatmo.errors import ConfigError, FormatError

M = TypeVar("M", bound=BaseModel)


#: options removed from a model, by name: the value each had by default (see
#: :attr:`GatmoModel.removed_options`)
_REMOVED: dict[str, Any] = {}


def _same(value: Any, default: Any) -> bool:
    """``value`` is ``default`` as YAML writes it (1 and 1.0 alike, but not True and 1)."""
    return isinstance(value, bool) == isinstance(default, bool) and value == default


class GatmoModel(BaseModel):
    """Base of every config model: unknown keys are errors, assignments are validated.

    ``removed_options`` (name -> the value it had by default): options a later version dropped.
    A file naming one at that value (a ``config.yaml`` an earlier run wrote, every field
    written out) still loads, the key ignored; at any other value it is refused as a removed
    option, as the behaviour it asked for is gone."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)
    removed_options: ClassVar[dict[str, Any]] = {}

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        _REMOVED.update(cls.__dict__.get("removed_options", {}))

    @model_validator(mode="before")
    @classmethod
    def _ignore_removed_at_their_defaults(cls, data: Any) -> Any:
        gone = cls.removed_options
        if gone and isinstance(data, dict):
            data = {k: v for k, v in data.items()
                    if not (k in gone and _same(v, gone[k]))}
        return data


def yaml_key_lines(text: str) -> dict[tuple, int]:
    """Map each key path in a YAML document to its 1-based line number."""
    try:
        root = yaml.compose(text)
    except yaml.YAMLError:
        return {}
    out: dict[tuple, int] = {}

    def walk(node, path):
        if isinstance(node, yaml.MappingNode):
            for k, v in node.value:
                key = k.value
                out[path + (key,)] = k.start_mark.line + 1
                walk(v, path + (key,))
        elif isinstance(node, yaml.SequenceNode):
            for i, v in enumerate(node.value):
                out[path + (i,)] = v.start_mark.line + 1
                walk(v, path + (i,))

    if root is not None:
        walk(root, ())
    return out


def read_yaml(path: str | Path) -> tuple[Any, str]:
    """Read a YAML file; return (data, text). Syntax errors become FormatError with the line."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise FormatError(f"cannot read: {exc.strerror or exc}", file=path) from exc
    except UnicodeDecodeError as exc:
        raise FormatError("not a text file", file=path) from exc
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        line = None
        mark = getattr(exc, "problem_mark", None)
        if mark is not None:
            line = mark.line + 1
        raise FormatError(
            f"invalid YAML: {getattr(exc, 'problem', exc)}", file=path, line=line
        ) from exc
    return data, text


def validation_to_config_error(
    exc: ValidationError,
    *,
    file: str | Path | None = None,
    lines: dict[tuple, int] | None = None,
    prefix: tuple = (),
    key_names: dict[str, str] | None = None,
) -> ConfigError:
    """Turn the first pydantic error into a ConfigError naming file, line and key.

    ``key_names`` maps model field names back to the names the user wrote (e.g. ROS parameter
    names), so messages speak the user's language.
    """
    err = exc.errors()[0]
    loc = tuple(err.get("loc", ()))
    names = [key_names.get(str(p), str(p)) if key_names else str(p) for p in loc]
    field = ".".join(names) if names else None
    line = None
    if lines:
        user_loc = tuple(key_names.get(str(p), p) if key_names else p for p in loc)
        line = lines.get(prefix + user_loc) or lines.get(prefix + loc[:1])
    msg = err.get("msg", "invalid value")
    if err.get("type") == "extra_forbidden" and names and names[-1] in _REMOVED:
        msg = (f"removed option (docs/experiments.md): only the value it had by default, "
               f"{_REMOVED[names[-1]]!r}, is still accepted (got {err.get('input')!r})")
    elif err.get("type") == "extra_forbidden":
        msg = "unknown key"
    elif err.get("type") == "value_error" and isinstance(err.get("input"), dict):
        # a model's own check across its fields: its message names them and their values
        msg = msg.removeprefix("Value error, ")
    elif "input" in err and err.get("type") != "missing":
        msg = f"{msg} (got {err['input']!r})"
    return ConfigError(msg, file=file, line=line, field=field)


def load_model(model: type[M], path: str | Path, *, section: str | None = None) -> M:
    """Load ``model`` from a YAML file (optionally from a top-level ``section``)."""
    data, text = read_yaml(path)
    prefix: tuple = ()
    if section is not None and isinstance(data, dict) and section in data:
        data = data[section]
        prefix = (section,)
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError("expected a mapping of parameters", file=path)
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise validation_to_config_error(
            exc, file=path, lines=yaml_key_lines(text), prefix=prefix
        ) from None


def dump_model(cfg: BaseModel, *, comments: bool = False) -> str:
    """YAML text of a model, every field written out (defaults included). ``comments``: each
    key is preceded by its field's description as ``#`` lines, wrapped at 100 columns (what a
    user editing the file needs; the values and the data loaded back are the same)."""
    data = cfg.model_dump(mode="json")
    if not comments:
        return yaml.safe_dump(data, sort_keys=False)
    lines: list[str] = []
    _commented(cfg, data, 0, lines)
    return "\n".join(lines) + "\n"


def _commented(cfg: BaseModel, data: dict, indent: int, lines: list[str]) -> None:
    """Append the YAML lines of ``data`` (``cfg`` dumped) to ``lines``, every key after its
    description as comments, nested models indented under their key."""
    import textwrap

    pad = " " * indent
    for name, field in type(cfg).model_fields.items():
        if name not in data:
            continue
        if field.description:
            width = max(40, 100 - indent - 2)
            lines += [f"{pad}# {t}" for t in textwrap.wrap(field.description, width)]
        value = getattr(cfg, name)
        if isinstance(value, BaseModel):
            lines.append(f"{pad}{name}:")
            _commented(value, data[name], indent + 2, lines)
        else:
            text = yaml.safe_dump({name: data[name]}, sort_keys=False).rstrip("\n")
            lines += [pad + t for t in text.split("\n")]
