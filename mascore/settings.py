"""Settings dataclasses that document and check themselves: :func:`setting`, :func:`check_settings`.

A study's (or a benchmark's) settings are a frozen dataclass whose fields are
declared with :func:`setting`: what each is (a paper's value, our choice, or
derived), its unit, and the values it takes. ``check_settings(self)`` in the
dataclass's ``__post_init__`` refuses any other value by the field's name;
:func:`show_settings` and :func:`documented_settings` lay them out for a reader.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .formatting import format_value

__all__ = [
    "SettingsView",
    "allowed_values",
    "check_settings",
    "check_settings_type",
    "documented_settings",
    "setting",
    "show_settings",
]


def setting(default: Any, *, source: str = "paper", where: str = "", unit: str = "", note: str = "",
            kind: str | None = None, low: float | None = None, high: float | None = None,
            low_open: bool = False, high_open: bool = False, choices: Sequence[Any] | None = None,
            length: int | None = None, check: Callable[[Any], str | None] | None = None) -> Any:
    """A settings-dataclass field that documents and checks itself.

    The declaration says what the field is (shown by :func:`show_settings` and
    :func:`documented_settings`) and which values it takes: ``check_settings``,
    called by the dataclass's ``__post_init__``, refuses any other value by the
    field's name, so construction and :func:`dataclasses.replace` both fail early.

    Parameters
    ----------
    default : object
        The value (use a tuple, not a list or array, to keep the dataclass frozen and hashable).
    source : {"paper", "chosen", "derived"}
        Given by the paper, chosen by us because the paper leaves it out, or derived from others.
    where : str
        Where the paper gives it (``"Table I"``) or why we chose it.
    unit : str
        Physical unit, ``""`` if dimensionless.
    note : str
        One short phrase on what it is.
    kind : {"real", "integer", "bool", "text", "choice", "reals", "integers", "matrix"}, optional
        What the value is: a finite number, an integer (not a bool), a bool, a string, one of
        `choices`, a tuple of finite numbers or of integers, or a rectangular tuple of tuples
        of finite numbers. Default: inferred from `default` (``"choice"`` when `choices` is given).
    low, high : float, optional
        Bounds of the value (of every entry for tuples and matrices).
    low_open, high_open : bool
        Whether the bound itself is excluded (``low=0, low_open=True`` means ``> 0``).
    choices : sequence, optional
        The allowed values of a ``"choice"``.
    length : int, optional
        Required number of entries of a tuple (``"reals"``, ``"integers"``).
    check : callable, optional
        ``check(value) -> None`` if the value is allowed, else a phrase naming what it must be
        (``"a (n, n) matrix"``); runs after the checks above.

    Returns
    -------
    dataclasses.Field
        The field, its metadata read by :func:`show_settings`, :func:`documented_settings`
        and ``check_settings``.

    Raises
    ------
    ValueError
        If `source` or `kind` is not one of the above.

    Examples
    --------
    >>> from dataclasses import dataclass, fields, replace
    >>> from mascore.settings import check_settings, setting
    >>> @dataclass(frozen=True)
    ... class Demo:
    ...     dt: float = setting(0.1, source="paper", where="Table I", unit="s", note="sampling time",
    ...                         low=0, low_open=True)
    ...     def __post_init__(self):
    ...         check_settings(self)
    >>> fields(Demo)[0].metadata["unit"]
    's'
    >>> replace(Demo(), dt=-0.1)
    Traceback (most recent call last):
    ...
    ValueError: Demo.dt must be a finite number > 0 s; got -0.1
    """
    if source not in ("paper", "chosen", "derived"):
        raise ValueError(f"source must be 'paper', 'chosen' or 'derived'; got {source!r}")
    if kind is None:
        kind = "choice" if choices is not None else _infer_kind(default)
    if kind not in _KINDS:
        raise ValueError(f"kind must be one of {', '.join(_KINDS)}; got {kind!r}")
    if kind == "choice" and not choices:
        raise ValueError("a 'choice' setting needs its choices")
    return field(default=default, metadata={
        "source": source, "where": where, "unit": unit, "note": note, "kind": kind, "low": low, "high": high,
        "low_open": bool(low_open), "high_open": bool(high_open),
        "choices": tuple(choices) if choices is not None else None, "length": length, "check": check})


#: What a :func:`setting` can be (its ``kind``).
_KINDS = ("real", "integer", "bool", "text", "choice", "reals", "integers", "matrix")


def _is_int(x: Any) -> bool:
    return isinstance(x, (int, np.integer)) and not isinstance(x, (bool, np.bool_))


def _is_real(x: Any) -> bool:
    return isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, (bool, np.bool_))


def _infer_kind(default: Any) -> str:
    if isinstance(default, (bool, np.bool_)):
        return "bool"
    if _is_int(default):
        return "integer"
    if _is_real(default):
        return "real"
    if isinstance(default, str):
        return "text"
    if isinstance(default, tuple) and default and all(_is_real(x) for x in default):
        return "integers" if all(_is_int(x) for x in default) else "reals"
    if isinstance(default, tuple) and default and all(isinstance(r, tuple) for r in default):
        return "matrix"
    raise ValueError(f"cannot infer the kind of a setting from its default {default!r}; give kind=")


def _fmt_bound(x: float) -> str:
    return format(x, "g") if isinstance(x, float) else str(x)


def _range_text(meta: Mapping[str, Any]) -> str:
    """The bounds of a setting as text: ``"> 0"``, ``"in [0, 1]"``, ``""`` when unbounded."""
    low, high = meta.get("low"), meta.get("high")
    if low is not None and high is not None:
        return (f"in {'(' if meta.get('low_open') else '['}{_fmt_bound(low)}, {_fmt_bound(high)}"
                f"{')' if meta.get('high_open') else ']'}")
    if low is not None:
        return f"{'>' if meta.get('low_open') else '>='} {_fmt_bound(low)}"
    if high is not None:
        return f"{'<' if meta.get('high_open') else '<='} {_fmt_bound(high)}"
    return ""


def allowed_values(meta: Mapping[str, Any]) -> str:
    """What a :func:`setting` accepts, in words (its field's ``metadata``), without the unit.

    Parameters
    ----------
    meta : mapping
        The ``metadata`` of a field declared with :func:`setting`.

    Returns
    -------
    str
        E.g. ``"a finite number > 0"``, ``"an integer in [1, 10]"``, ``"one of 'sdp', 'closed_form'"``.

    Examples
    --------
    >>> import dataclasses
    >>> from mascore.papers import song2023
    >>> from mascore.settings import allowed_values
    >>> field = {f.name: f for f in dataclasses.fields(song2023.SETTINGS)}["dt"]
    >>> allowed_values(field.metadata)
    'a finite number > 0'
    """
    kind, bounds = meta.get("kind"), _range_text(meta)
    length = meta.get("length")
    many = f"a tuple of {length} " if length else "a non-empty tuple of "
    text = {"real": "a finite number", "integer": "an integer", "bool": "True or False", "text": "a string",
            "reals": many + "finite numbers", "integers": many + "integers",
            "matrix": "a rectangular tuple of tuples of finite numbers"}.get(kind, "")
    if kind == "choice":
        return "one of " + ", ".join(repr(c) for c in meta["choices"])
    if bounds:
        text += (" " if kind in ("real", "integer") else ", each ") + bounds
    return text


def _reader_range(meta: Mapping[str, Any]) -> str:
    """The values a setting takes, as the settings table shows them to a reader: ``"> 0"``,
    ``"0 to 1"``, ``"whole number ≥ 1"``, ``"'sdp' or 'closed_form'"`` (:func:`allowed_values` words
    it for error messages)."""
    low, high = meta.get("low"), meta.get("high")
    lo = None if low is None else ("> " if meta.get("low_open") else "\u2265 ") + _fmt_bound(low)
    hi = None if high is None else ("< " if meta.get("high_open") else "\u2264 ") + _fmt_bound(high)
    if lo and hi and not meta.get("low_open") and not meta.get("high_open"):
        bounds = f"{_fmt_bound(low)} to {_fmt_bound(high)}"
    else:
        bounds = ", ".join(b for b in (lo, hi) if b)
    kind = meta.get("kind")
    if kind == "choice":
        choices = [repr(c) for c in meta["choices"]]
        return " or ".join(choices) if len(choices) <= 2 else ", ".join(choices[:-1]) + " or " + choices[-1]
    if kind == "bool":
        return "yes or no"
    if kind == "text":
        return "text"
    if kind == "matrix":
        return "a matrix"
    if kind in ("reals", "integers"):
        what = "whole numbers" if kind == "integers" else "numbers"
        count = f"{meta['length']} {what}" if meta.get("length") else what
        return f"{count}, each {bounds}" if bounds else count
    if kind == "integer":
        return f"whole number {bounds}".strip()
    return bounds or "any number"


def _setting_error(settings: Any, f: dataclasses.Field, value: Any, what: str | None = None,
                   error: type[Exception] = ValueError) -> Exception:
    meta = f.metadata
    what = what or allowed_values(meta)
    unit = f" {meta['unit']}" if meta.get("unit") and meta.get("kind") in ("real", "reals", "matrix") else ""
    shown = repr(value)
    if len(shown) > 80:
        shown = shown[:77] + "..."
    return error(f"{type(settings).__name__}.{f.name} must be {what}{unit}; got {shown}")


def _in_range(x: float, meta: Mapping[str, Any]) -> bool:
    low, high = meta.get("low"), meta.get("high")
    if low is not None and (x < low or (meta.get("low_open") and x == low)):
        return False
    return not (high is not None and (x > high or (meta.get("high_open") and x == high)))


def check_settings(settings: Any) -> None:
    """Check every field of a settings dataclass against its :func:`setting` declaration.

    Call it first thing in the dataclass's ``__post_init__``; construction and
    :func:`dataclasses.replace` then refuse a bad value with an error naming the
    class, the field, the allowed values and the unit. A list or array given for a
    tuple field is stored as a tuple (the dataclass stays frozen and hashable).
    Fields not declared with :func:`setting` are not checked.

    Parameters
    ----------
    settings : dataclass instance
        The settings being built.

    Raises
    ------
    TypeError
        If a field has the wrong type (a float for an integer, a string for a number, ...).
    ValueError
        If a field is out of its range, not finite, or not one of its choices.

    Examples
    --------
    >>> import dataclasses
    >>> from mascore.papers import ren2005
    >>> dataclasses.replace(ren2005.SETTINGS, n_steps=0)
    Traceback (most recent call last):
    ...
    ValueError: KalmanConsensusSettings.n_steps must be an integer >= 1; got 0
    """
    if not dataclasses.is_dataclass(settings) or isinstance(settings, type):
        raise TypeError(f"settings must be a dataclass instance; got {type(settings).__name__}")
    for f in dataclasses.fields(settings):
        meta = f.metadata
        kind = meta.get("kind")
        if kind is None:
            continue
        value = getattr(settings, f.name)
        if kind in ("reals", "integers", "matrix") and isinstance(value, (list, np.ndarray)):
            value = _as_tuple(value)
            object.__setattr__(settings, f.name, value)
        _check_field(settings, f, value, kind, meta)
        check = meta.get("check")
        if check is not None:
            problem = check(value)
            if problem:
                raise _setting_error(settings, f, value, problem)


def _as_tuple(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, list):
        return tuple(_as_tuple(v) for v in value)
    return value


def _check_field(settings: Any, f: dataclasses.Field, value: Any, kind: str, meta: Mapping[str, Any]) -> None:
    if kind == "bool":
        if not isinstance(value, (bool, np.bool_)):
            raise _setting_error(settings, f, value, error=TypeError)
    elif kind == "text":
        if not isinstance(value, str):
            raise _setting_error(settings, f, value, error=TypeError)
    elif kind == "choice":
        try:
            ok = value in meta["choices"]
        except TypeError:  # an unhashable value
            ok = False
        if not ok:
            raise _setting_error(settings, f, value)
    elif kind in ("real", "integer"):
        if not (_is_int(value) if kind == "integer" else _is_real(value)):
            raise _setting_error(settings, f, value, error=TypeError)
        if not np.isfinite(float(value)) or not _in_range(float(value), meta):
            raise _setting_error(settings, f, value)
    else:
        if not isinstance(value, tuple):
            raise _setting_error(settings, f, value, error=TypeError)
        rows = value if kind == "matrix" else (value,)
        if kind == "matrix" and not (rows and all(isinstance(r, tuple) and r for r in rows)
                                     and len({len(r) for r in rows}) == 1):
            raise _setting_error(settings, f, value, error=TypeError)
        if not rows[0] or (meta.get("length") is not None and len(value) != meta["length"]):
            raise _setting_error(settings, f, value)
        entry = _is_int if kind == "integers" else _is_real
        if not all(entry(x) for r in rows for x in r):
            raise _setting_error(settings, f, value, error=TypeError)
        if not all(np.isfinite(float(x)) and _in_range(float(x), meta) for r in rows for x in r):
            raise _setting_error(settings, f, value)


def check_settings_type(settings: Any, cls: type, name: str = "settings") -> Any:
    """Return `settings` if it is an instance of `cls`, else raise ``TypeError`` naming `name`.

    Parameters
    ----------
    settings : object
        The argument.
    cls : type
        The settings dataclass it must be.
    name : str
        The argument's name.

    Returns
    -------
    object
        `settings`.

    Examples
    --------
    >>> from mascore.papers import ren2005
    >>> from mascore.settings import check_settings_type
    >>> check_settings_type(ren2005.SETTINGS, ren2005.KalmanConsensusSettings) is ren2005.SETTINGS
    True
    """
    if not isinstance(settings, cls):
        raise TypeError(f"{name} must be a {cls.__name__} (change one with dataclasses.replace); "
                        f"got {type(settings).__name__}")
    return settings


def documented_settings(settings_class: type) -> type:
    """Complete a settings dataclass's docstring from its :func:`setting` fields.

    Appends a numpydoc Parameters section (one entry per field: its default with unit,
    whether the paper gives it or we chose it, the note and the allowed values) and an Examples section,
    so the API reference shows every setting of a paper without a second copy of them.
    Apply it above ``@dataclass``.

    Parameters
    ----------
    settings_class : type
        A dataclass whose fields were declared with :func:`setting`.

    Returns
    -------
    type
        `settings_class`, with its ``__doc__`` completed.

    Raises
    ------
    TypeError
        If `settings_class` is not a dataclass, or defines no ``__post_init__`` (which must call
        ``check_settings``).

    Examples
    --------
    >>> from mascore.papers.ren2005 import KalmanConsensusSettings
    >>> "Omega : " in KalmanConsensusSettings.__doc__
    True
    """
    if not (isinstance(settings_class, type) and dataclasses.is_dataclass(settings_class)):
        raise TypeError(f"documented_settings needs a dataclass; got {settings_class!r}")
    if "__post_init__" not in vars(settings_class):
        raise TypeError(f"{settings_class.__name__} must check its fields: define __post_init__ calling "
                        f"mascore.settings.check_settings(self)")
    lines = [(settings_class.__doc__ or settings_class.__name__).rstrip(), "", "Parameters", "----------"]
    for f in dataclasses.fields(settings_class):
        meta = f.metadata
        default = f.default if f.default is not dataclasses.MISSING else f.default_factory()  # type: ignore[misc]
        value = format_value(default, max_items=6) + (f" {meta['unit']}" if meta.get("unit") else "")
        origin = {"paper": "the paper", "chosen": "our choice", "derived": "derived"}.get(meta.get("source"), "")
        if meta.get("where"):
            origin += f", {meta['where']}"
        text = f"{meta.get('note') or f.name} ({origin})." if origin else f"{meta.get('note') or f.name}."
        if meta.get("kind"):
            text += f" Allowed: {allowed_values(meta)}" + (f" {meta['unit']}." if meta.get("unit") and meta.get(
                "kind") in ("real", "reals", "matrix") else ".")
        lines += [f"{f.name} : default {_rst(value)}", f"    {_rst(text)}"]
    first = dataclasses.fields(settings_class)[0].name
    lines += ["", "Examples", "--------", ">>> import dataclasses",
              f">>> from {settings_class.__module__} import {settings_class.__name__}",
              f">>> settings = {settings_class.__name__}()",
              f">>> changed = dataclasses.replace(settings, {first}=settings.{first})   # change any setting by name",
              ">>> changed == settings", "True"]
    settings_class.__doc__ = "\n".join(lines)
    return settings_class


@dataclass(frozen=True)
class SettingsView:
    """A settings dataclass laid out as a Markdown table (Jupyter shows it as such).

    Parameters
    ----------
    settings : dataclass instance
        Settings declared with :func:`setting`.

    Examples
    --------
    >>> from mascore.papers import ren2005
    >>> from mascore.settings import SettingsView
    >>> str(SettingsView(ren2005.SETTINGS)).splitlines()[0]
    '| setting | value | allowed values | from | note |'
    """

    settings: Any

    def _repr_markdown_(self) -> str:
        rows = ["| setting | value | allowed values | from | note |", "|---|---|---|---|---|"]
        for f in dataclasses.fields(self.settings):
            meta = f.metadata
            value = format_value(getattr(self.settings, f.name), max_items=12)
            if meta.get("unit"):
                value += f" {meta['unit']}"
            origin = {"paper": "paper", "chosen": "**our choice**", "derived": "derived"}.get(meta.get("source"), "")
            if meta.get("where"):
                origin += f" ({meta['where']})"
            allowed = _reader_range(meta) if meta.get("kind") else ""
            rows.append(f"| `{f.name}` | {_cell(value)} | {_cell(allowed)} | {_cell(origin)} "
                        f"| {_cell(meta.get('note', ''))} |")
        return "\n".join(rows)

    __str__ = _repr_markdown_


def show_settings(settings: Any) -> SettingsView:
    """Display a settings dataclass as a table: value with unit, whether the paper gives it, a note.

    Parameters
    ----------
    settings : dataclass instance
        Settings declared with :func:`setting`.

    Returns
    -------
    SettingsView
        Shown as a Markdown table by Jupyter.

    Raises
    ------
    TypeError
        If `settings` is not a dataclass instance.

    Examples
    --------
    >>> from mascore.papers import song2023
    >>> from mascore.settings import show_settings
    >>> "sampling time" in str(show_settings(song2023.SETTINGS))
    True
    """
    if not dataclasses.is_dataclass(settings):
        raise TypeError(f"settings must be a dataclass instance; got {type(settings).__name__}")
    return SettingsView(settings)


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _rst(text: str) -> str:
    """MyST text of a setting as reStructuredText: ``$x$`` as :math:`x`, ``|x|`` not a substitution."""
    text = text.replace("|", "\\|")
    return re.sub(r"\$([^$]+)\$", lambda m: ":math:`" + m.group(1).replace("\\|", "|") + "`", text)
