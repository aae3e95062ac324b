"""How the book prints a number, a value with its unit, a list or a mapping: one place for every page."""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["format_number", "format_value", "math_text"]


_SUPERSCRIPT = str.maketrans("-0123456789", "\u207b\u2070\u00b9\u00b2\u00b3\u2074\u2075\u2076\u2077\u2078\u2079")


def format_number(x: float, digits: int = 4) -> str:
    """One number as the book prints it: `digits` significant digits, no ``e`` notation.

    Numbers from 1e-3 to below 1e6 are written out (``0.07681``, ``2.462``, ``136.4``,
    ``12,346``); smaller and larger ones as ``2.776 × 10⁻¹⁷``. Integers are written
    exactly; a boolean as ``yes`` or ``no``. Trailing zeros are dropped.

    Parameters
    ----------
    x : float
        The number.
    digits : int
        Significant digits.

    Returns
    -------
    str
        The number as printed.

    Examples
    --------
    >>> format_number(0.076812345), format_number(2.7755575615628914e-17), format_number(5.0)
    ('0.07681', '2.776 × 10⁻¹⁷', '5')
    """
    if isinstance(digits, bool) or not isinstance(digits, int | np.integer):
        raise TypeError(f"digits must be an integer >= 1 (significant digits); got {type(digits).__name__} {digits!r}")
    if not 1 <= digits <= 17:
        raise ValueError(f"digits must be an integer >= 1 and at most 17 (significant digits of a float); got {digits}")
    digits = int(digits)
    if isinstance(x, bool | np.bool_):
        return "yes" if x else "no"
    if isinstance(x, int | np.integer):
        return f"{int(x):,}" if abs(int(x)) >= 10_000 else str(int(x))
    if isinstance(x, str | bytes) or not hasattr(x, "__float__"):
        raise TypeError(f"x must be a real number; got {type(x).__name__} {x!r}")
    x = float(x)
    if not math.isfinite(x):
        return str(x)
    if x == 0.0:
        return "0"
    exponent = math.floor(math.log10(abs(x)))
    if -3 <= exponent < 6:
        decimals = max(digits - 1 - exponent, 0)
        text = f"{x:,.{decimals}f}"
        if "." in text:
            text = text.rstrip("0").rstrip(".")
        return "0" if text in ("-0", "") else text
    mantissa = f"{x / 10.0**exponent:.{digits - 1}f}".rstrip("0").rstrip(".")
    if mantissa in ("10", "-10"):  # rounding carried into the next decade
        mantissa, exponent = mantissa[:-1], exponent + 1
    return f"{mantissa} \u00d7 10{str(exponent).translate(_SUPERSCRIPT)}"


def format_value(value: Any, digits: int = 4, max_items: int = 4, unit: str = "",
                 labels: Sequence[str] | None = None) -> str:
    """A short human-readable form of a claim value.

    Numbers through :func:`format_number` (with `unit` appended), lists labelled by
    `labels` when given and cut after `max_items` entries (marked with an ellipsis),
    dicts as ``label = value`` pairs (underscores in labels read as spaces), booleans
    as ``yes`` / ``no``, ``None`` as a dash. Any value is shown, by design: NaN and infinities print as ``nan`` and
    ``inf``, a string as itself (this is a display helper; :class:`mascore.claims.Claim` refuses them).

    Parameters
    ----------
    value : object
        A number, list, dict or None.
    digits : int
        Significant digits of each number.
    max_items : int
        Entries shown of a list.
    unit : str
        Appended to numbers.
    labels : sequence of str, optional
        Names of a list's entries.

    Returns
    -------
    str
        The value as printed.

    Examples
    --------
    >>> from mascore.ledger import format_value
    >>> format_value([1.5, 2.25], labels=["mean", "rms"], unit="m")
    'mean: 1.5; rms: 2.25 (m)'
    """
    for name, count in (("digits", digits), ("max_items", max_items)):
        if isinstance(count, bool) or not isinstance(count, int | np.integer):
            raise TypeError(f"{name} must be an integer >= 1; got {type(count).__name__} {count!r}")
        if count < 1:
            raise ValueError(f"{name} must be an integer >= 1; got {count}")
    if not isinstance(unit, str):
        raise TypeError(f"unit must be a string; got {type(unit).__name__}")
    suffix = f"\u00a0{unit}" if unit else ""
    if value is None:
        return "\u2014"
    if isinstance(value, bool | np.bool_):
        return "yes" if value else "no"
    if isinstance(value, int | float | np.integer | np.floating):
        return format_number(value, digits) + suffix
    if isinstance(value, str):
        return value
    if isinstance(value, dict):
        def item(v: Any) -> str:
            text = format_value(v, digits, max_items)
            return "(" + text + ")" if isinstance(v, dict) else text

        items = [f"{_label(k)} = {item(v)}" for k, v in list(value.items())[:2 * max_items]]
        more = len(value) > 2 * max_items
        return "; ".join(items) + ("; \u2026" if more else "") + (f" ({unit})" if unit else "")
    if isinstance(value, list | tuple | np.ndarray):
        value = list(value)
        if labels is not None and len(labels) == len(value):
            pairs = [f"{lab}: {format_value(v, digits, max_items)}" for lab, v in zip(labels, value)]
            return "; ".join(pairs) + (f" ({unit})" if unit else "")
        items = [format_value(v, digits, max_items) for v in value[:max_items]]
        return "[" + ", ".join(items) + (", \u2026" if len(value) > max_items else "") + "]" + suffix
    return str(value)


def _label(key: Any) -> str:
    """A mapping key as text: an identifier's underscores as spaces (``last_k`` -> ``last k``); a label
    already written in words keeps its symbols (``largest |A_c^k|``)."""
    text = str(key)
    return text if " " in text else text.replace("_", " ")


_GREEK = ("alpha", "beta", "gamma", "delta", "epsilon", "lambda", "mu", "nu", "xi", "rho", "sigma", "tau", "phi",
          "omega", "Gamma", "Delta", "Lambda", "Sigma", "Phi", "Omega")
_BASE = r"(?:" + "|".join(_GREEK) + r"|[A-Za-z])"
_SUB = r"(?:_(?:bar|hat|[A-Za-z0-9]+))"
_SUP = r"(?:\^(?:\([A-Za-z0-9]+\)|-?[A-Za-z0-9]+))"
_NAME = rf"{_BASE}{_SUB}*{_SUP}?"


def _tex(name: str) -> str:
    """``delta_bar_k`` -> ``\\bar{\\delta}_{k}``; ``P_0`` -> ``P_{0}``; ``A_c^k`` -> ``A_{c}^{k}``."""
    name, _, power = name.partition("^")
    base, *parts = name.split("_")
    tex = f"\\{base}" if base in _GREEK else base
    for accent in ("bar", "hat"):
        if accent in parts:
            parts.remove(accent)
            tex = f"\\{accent}{{{tex}}}"
    tex += f"_{{{','.join(parts)}}}" if parts else ""
    if power:
        tex += "^\\top" if power == "T" else f"^{{{power}}}"
    return tex


def _root(name: str) -> str:
    """What ``sqrt(...)`` holds, in TeX: a symbol (``q_bar``, ``p0``) or an operator written out (``trace``)."""
    if name == "eps":
        return "\\varepsilon"
    return f"\\operatorname{{{name}}}" if re.fullmatch(r"[a-z]{4,}", name) else _tex(name)


def math_text(text: str) -> str:
    r"""A ledger statement's ASCII math as MyST math: ``|delta_bar_k|``, ``alpha_w``, ``P_0``, ``Q2``, ``0.9^k``.

    Bars around a name read as a norm, ``sqrt(x)`` as a root, ``xhat_0`` as :math:`\hat x_0`, ``<=`` as ``≤``
    and ``sup_k`` as a supremum; text without such names, and math already in ``$...$``, come back unchanged.

    Parameters
    ----------
    text : str
        Plain text with names written in ASCII (``alpha_w``, ``trace P_0``, ``|A_c^k|``).

    Returns
    -------
    str
        The text with those names in ``$...$``.

    Examples
    --------
    >>> from mascore.formatting import math_text
    >>> print(math_text("Mean of |delta_bar_k| with alpha_w = 0.05, trace P_0 = 4 and Q2 = 5."))
    Mean of $\lvert \bar{\delta}_{k} \rvert$ with $\alpha_{w}$ = 0.05, trace $P_{0}$ = 4 and $Q_2$ = 5.
    >>> print(math_text("|A_c^k| <= 1.1 * 0.9^k for all k; |B_c| sqrt(q_bar); sqrt(trace)"))
    $\lvert A_{c}^{k} \rvert$ ≤ 1.1 × $0.9^{k}$ for all k; $\lvert B_{c} \rvert$ $\sqrt{\bar{q}}$; $\sqrt{\operatorname{trace}}$
    >>> print(math_text("phi = 1 for vlahakis-phi1 and vlahakis-phi-0.1"))   # a hyphenated name is left alone
    $\phi$ = 1 for vlahakis-phi1 and vlahakis-phi-0.1
    """
    pieces = re.split(r"(\$[^$]*\$)", text)  # math already written as $...$ stays as it is
    return "".join(p if p.startswith("$") else _ascii_math(p) for p in pieces)


def _ascii_math(text: str) -> str:
    """:func:`math_text` on a piece of text without ``$...$``."""
    out = re.sub(rf"\|({_NAME})\|", lambda m: f"$\\lvert {_tex(m.group(1))} \\rvert$", text)
    out = re.sub(rf"sqrt\(({_NAME}|[A-Za-z]\w*)\)", lambda m: f"$\\sqrt{{{_root(m.group(1))}}}$", out)
    out = re.sub(r"(?<![\w$^])(\d+(?:\.\d+)?|[α-ω])\^([A-Za-z])\b", r"$\1^{\2}$", out)
    out = re.sub(r"\bsup_k\b", r"$\\sup_k$", out)
    out = re.sub(r"\b([a-z])hat_([A-Za-z0-9]+)\b", r"$\\hat{\1}_{\2}$", out)
    out = out.replace("<=", "≤").replace(" * ", " × ")
    greek = "|".join(_GREEK)
    # not inside a hyphenated name (a method such as vlahakis-phi-0.1 keeps its spelling)
    out = re.sub(rf"(?<![\\$\w{{-])((?:{greek}){_SUB}*{_SUP}?|[A-Za-z]{_SUB}+{_SUP}?|[A-Za-z]\^(?:T|-?[0-9]+))(?![\w$-])",
                 lambda m: f"${_tex(m.group(1))}$", out)
    return re.sub(r"(?<![\w$])(Q|R)([12])(?![\w$])", r"$\1_\2$", out)
