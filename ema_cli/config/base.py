"""The one pydantic base of every schema and the constrained types its fields share.

``Strict`` is frozen and closed (an unknown key is an error). The numeric types refuse NaN,
``inf`` and booleans (YAML reads ``yes``/``no``/``on``/``off`` as booleans, which pydantic would
otherwise take for 1 and 0); range caps that guard against resource exhaustion are set on the
fields themselves (``le=``), with the cap in the field description.

``PlainName`` is for every name that ends up in a file or folder name (run names, experiment
names, study and threshold ids, figure file names): letters, digits, ``_``, ``.``, ``-``, starting
with a letter or digit, at most 64 characters, so never a path separator, ``.`` or ``..``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from typing import Annotated, Any, Union

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Discriminator,
    Field,
    Tag,
)

from ema_cli.errors import EmaError


class Strict(BaseModel):
    """Base of every schema: frozen, closed (unknown keys are errors)."""

    model_config = ConfigDict(frozen=True, extra="forbid")


def _not_bool(value: Any) -> Any:
    if isinstance(value, bool):
        raise ValueError(f"expected a number, got the boolean {str(value).lower()} "
                         "(YAML reads yes/no/on/off/true/false as booleans)")
    return value


def _finite(value: Any) -> Any:
    """Refuse booleans and NaN/inf (also written as text, e.g. 'nan', '1e400') before any
    range check, so the message says what is wrong."""
    value = _not_bool(value)
    x = value
    if isinstance(value, str):
        try:
            x = float(value)
        except ValueError:
            return value  # pydantic reports the text that is not a number
    if isinstance(x, float) and not math.isfinite(x):
        raise ValueError(f"must be a finite number, got {value}")
    return value


FiniteFloat = Annotated[float, BeforeValidator(_finite), Field(allow_inf_nan=False)]
"""A finite number (NaN and inf refused)."""
PositiveFloat = Annotated[float, BeforeValidator(_finite), Field(gt=0, allow_inf_nan=False)]
"""A finite number > 0."""
NonNegFloat = Annotated[float, BeforeValidator(_finite), Field(ge=0, allow_inf_nan=False)]
"""A finite number >= 0."""
PositiveInt = Annotated[int, BeforeValidator(_not_bool), Field(ge=1)]
"""An integer >= 1 (give the field an upper cap with ``le=``)."""
NonNegInt = Annotated[int, BeforeValidator(_not_bool), Field(ge=0)]
"""An integer >= 0 (give the field an upper cap with ``le=``)."""
Integer = Annotated[int, BeforeValidator(_not_bool)]
"""An integer, not a boolean (give the field its range with ``ge=``/``le=``)."""

MAX_SEED = 2**63 - 1
"""The largest seed accepted (fits a signed 64-bit integer)."""
Seed = Annotated[int, BeforeValidator(_not_bool), Field(ge=0, le=MAX_SEED)]
"""A seed: an integer 0 .. 2**63-1."""

NAME_MAX_LEN = 64
NAME_PATTERN = re.compile(rf"^[A-Za-z0-9][A-Za-z0-9._-]{{0,{NAME_MAX_LEN - 1}}}$")
NAME_RULE = (f"a plain name (letters, digits, '_', '.', '-'; starting with a letter or digit; "
             f"at most {NAME_MAX_LEN} characters; no path separators or '..') as it becomes a "
             "file or folder name")


def _short(value: str, width: int = 40) -> str:
    text = repr(value)
    return text if len(text) <= width else text[:width] + "...'"


def check_plain_name(value: Any, what: str = "") -> str:
    """``value`` if it is a plain file/folder name (see :data:`NAME_RULE`), else EmaError
    (``what`` names the value at the start of the message)."""
    head = f"{what} must be" if what else "must be"
    if not isinstance(value, str):
        raise EmaError(f"{head} {NAME_RULE}, got {type(value).__name__}")
    if not NAME_PATTERN.fullmatch(value) or ".." in value:
        got = "an empty string" if not value else _short(value)
        raise EmaError(f"{head} {NAME_RULE}, got {got}")
    return value


def _plain_name(value: str) -> str:
    try:
        return check_plain_name(value)
    except EmaError as exc:
        raise ValueError(exc.message) from None


PlainName = Annotated[str, AfterValidator(_plain_name)]
"""A name safe to use as one file or folder name (never a path)."""


def tagged_union(key: str, classes: Mapping[str, type]) -> Any:
    """The union of ``classes`` (tag -> schema) told apart by the entry's ``key`` field (e.g.
    ``test: step``, ``dist: normal``); each member tagged ``KEY[TAG]``, a ``loc`` element the
    loader drops from its messages (``loader._UNION_TAG``)."""

    def tag(v: Any) -> str:
        name = v.get(key) if isinstance(v, dict) else getattr(v, key, None)
        return f"{key}[{name}]"

    return Annotated[Union[tuple(Annotated[cls, Tag(f"{key}[{k}]")]  # noqa: UP007
                                 for k, cls in classes.items())], Discriminator(tag)]

