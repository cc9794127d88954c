"""A pydantic `ValidationError` of the rig config as one line naming the key path.

``sinks.modbus_status.port must be a TCP port 0..65535 (0 = any free port) (got 70000)``,
``link.wrd_order: unknown key (did you mean 'word_order'?)``: the wording of the config's
errors before pydantic, with the typo suggestion of the model file's keys
(`fdi_daemon.io.known_keys.close_match`).
"""

from __future__ import annotations

import inspect
from collections.abc import Sequence
from typing import Any, get_args

from pydantic import BaseModel, ValidationError
from pydantic_core import ErrorDetails

from fdi_daemon.io.known_keys import close_match

__all__ = ["one_line", "key_path"]

#: pydantic error type -> what the value must be
_TYPE_NAMES = {
    "int_type": "a whole number",
    "float_type": "a number",
    "string_type": "a string",
    "bool_type": "true or false",
    "list_type": "a list",
    "dict_type": "a mapping",
    "model_type": "a mapping",
}


def key_path(loc: Sequence[int | str]) -> str:
    """``('simulated_device', 'faults', 0, 'at_s')`` -> ``simulated_device.faults[0].at_s``."""
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else f"{'.' if out else ''}{part}"
    return out


def one_line(exc: ValidationError, root: type[BaseModel]) -> str:
    """The first problem of ``exc`` (validating ``root``) as one line; a count of the rest."""
    problems = exc.errors(include_url=False)
    line = _describe(problems[0], root)
    if len(problems) > 1:
        line += f" (and {len(problems) - 1} more problem(s))"
    return line


def _describe(error: ErrorDetails, root: type[BaseModel]) -> str:
    loc, kind, given = error["loc"], error["type"], error["input"]
    path = key_path(loc)
    if kind == "extra_forbidden":
        known = list(_model_at(root, loc[:-1]).model_fields)
        close = close_match(loc[-1], known)
        hint = f"did you mean {close!r}?" if close else f"known: {', '.join(known)}"
        return f"{path}: unknown key ({hint})"
    if kind == "missing":
        about = _model_at(root, loc[:-1]).model_fields[str(loc[-1])].description
        return f"{path} is required" + (f" ({about})" if about else "")
    if kind == "value_error":
        problem = str(error.get("ctx", {}).get("error", error["msg"]))
        return f"{path} {problem} (got {given!r})"
    if kind in _TYPE_NAMES:
        if given is None:
            default = (
                _model_at(root, loc[:-1])
                .model_fields[str(loc[-1])]
                .get_default(call_default_factory=True)
            )
            return f"{path} may not be null (default {_plain(default)!r})"
        if _TYPE_NAMES[kind] == "a mapping":
            return f"{path} must be a mapping"
        return f"{path} must be {_TYPE_NAMES[kind]}, not {given!r}"
    return f"{path}: {error['msg']}"


def _plain(value: Any) -> Any:
    return value.model_dump() if isinstance(value, BaseModel) else value


def _model_at(root: type[BaseModel], loc: Sequence[int | str]) -> type[BaseModel]:
    """The model class that validates the mapping at ``loc`` (list indices skipped)."""
    model = root
    for part in loc:
        if isinstance(part, str):
            inner = _inner_model(model.model_fields[part].annotation)
            if inner is None:
                break
            model = inner
    return model


def _inner_model(annotation: Any) -> type[BaseModel] | None:
    """The BaseModel inside ``X | None``, ``list[X]`` or ``Annotated[X, ...]``."""
    if inspect.isclass(annotation) and issubclass(annotation, BaseModel):
        return annotation
    for arg in get_args(annotation):
        if (found := _inner_model(arg)) is not None:
            return found
    return None
