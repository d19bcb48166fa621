"""Hypothesis settings and damage strategies shared by the property tests.

Two settings profiles:

- ``ci`` (the default, used by ``make test``): derandomized (the same examples on every run,
  no example database), each test with its own small example count so the directory runs
  in well under a minute;
- ``fuzz`` (``make fuzz``, selected with ``UAV_FUZZ=1``): random examples, ``UAV_FUZZ_EXAMPLES``
  (default 10 000) per test, except the in-process node test, which runs one node per example
  and takes ``UAV_FUZZ_NODE_EXAMPLES`` (default 200).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any, TypeVar

from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

FUZZ = os.environ.get("UAV_FUZZ", "") not in ("", "0")
FUZZ_EXAMPLES = int(os.environ.get("UAV_FUZZ_EXAMPLES", "10000"))
FUZZ_NODE_EXAMPLES = int(os.environ.get("UAV_FUZZ_NODE_EXAMPLES", "200"))

_COMMON: dict[str, Any] = {
    "deadline": None,
    "database": None,
    "suppress_health_check": [
        HealthCheck.too_slow,
        HealthCheck.data_too_large,
        HealthCheck.function_scoped_fixture,
    ],
}
settings.register_profile("ci", derandomize=True, print_blob=True, **_COMMON)
settings.register_profile("fuzz", derandomize=False, print_blob=True, **_COMMON)
settings.load_profile("fuzz" if FUZZ else "ci")

F = TypeVar("F", bound=Callable[..., Any])


def examples(ci: int, fuzz: int | None = None) -> Callable[[F], F]:
    """Settings with ``ci`` examples in CI and ``fuzz`` (default UAV_FUZZ_EXAMPLES) in fuzz."""
    n = (FUZZ_EXAMPLES if fuzz is None else fuzz) if FUZZ else ci
    return settings(max_examples=n)


# --- damaged text -------------------------------------------------------------------------

#: Field values that break parsers: non-finite, 400-digit, empty, odd Unicode, stray quotes,
#: carriage returns, huge and negative numbers, -999.
NASTY_FIELDS: tuple[str, ...] = (
    "NaN",
    "nan",
    "inf",
    "-inf",
    "Infinity",
    "1e400",
    "-1e400",
    "9" * 400,
    "9" * 5000,
    "-" + "9" * 400,
    "0." + "1" * 400,
    "",
    " ",
    "-999",
    "0",
    "-0",
    "1e308",
    "-1e308",
    "5e-324",
    '"',
    '""',
    '"a,b',
    "\r",
    "a\rb",
    "\x00",
    "\ufeff",
    "\u2028",
    "\u202e",
    "\U0001f681",
    "ｌａｔ",
    "١٢٣",
    "٣٥.٧",
    "35,7",
    "(1,2,3)",
    "(nan,inf,-inf)",
    "()",
    "null",
    "[]",
    "{}",
    "true",
    "2025-13-45 25:61:61",
    "2025-10-07 19:42:20.000Z",
    "2025-10-07T19:42:20+14:00",
    "9999-12-31 23:59:59",
    "0000-01-01 00:00:00",
    "1759866140",
    "1759866140000",
)

nasty_text = st.one_of(st.sampled_from(NASTY_FIELDS), st.text(max_size=12))


@st.composite
def damaged_lines(draw: st.DrawFn, lines: list[bytes], sep: bytes = b",") -> bytes:
    """``lines`` (each without its newline) with 1-4 kinds of damage, as file bytes.

    Damage: byte flips, truncation, duplicated / deleted / shuffled / swapped lines, garbage
    lines, a field replaced by a nasty value, a carriage return dropped into a line.
    """
    out = list(lines)
    for _ in range(draw(st.integers(1, 4))):
        kind = draw(
            st.sampled_from(
                ("flip", "dup", "delete", "swap", "shuffle", "garbage", "field", "cr", "truncate")
            )
        )
        if not out:
            out = [b""]
        i = draw(st.integers(0, len(out) - 1))
        if kind == "flip":
            line = bytearray(out[i] or b" ")
            k = draw(st.integers(0, len(line) - 1))
            line[k] ^= draw(st.integers(1, 255))
            out[i] = bytes(line)
        elif kind == "dup":
            out.insert(i, out[i])
        elif kind == "delete":
            del out[i]
        elif kind == "swap":
            j = draw(st.integers(0, len(out) - 1))
            out[i], out[j] = out[j], out[i]
        elif kind == "shuffle":
            j = min(len(out), i + draw(st.integers(2, 8)))
            part = out[i:j]
            out[i:j] = draw(st.permutations(part))
        elif kind == "garbage":
            g = draw(st.one_of(st.binary(max_size=40), nasty_text.map(lambda s: s.encode())))
            out.insert(i, g.replace(b"\n", b" "))
        elif kind == "field":
            parts = out[i].split(sep)
            k = draw(st.integers(0, len(parts) - 1))
            parts[k] = draw(nasty_text).encode("utf-8", "surrogatepass").replace(b"\n", b"")
            out[i] = sep.join(parts)
        elif kind == "cr":
            k = draw(st.integers(0, len(out[i])))
            out[i] = out[i][:k] + b"\r" + out[i][k:]
        else:  # truncate somewhere in the file
            data = b"\n".join(out)
            cut = draw(st.integers(0, len(data)))
            return data[:cut]
    data = b"\n".join(out)
    return data + b"\n" if data else data


def count_data_lines(data: bytes) -> int:
    """Non-blank lines of a file as the readers count them (split on LF, BOM dropped)."""
    raw = data.split(b"\n")
    if raw and raw[-1] == b"":
        raw.pop()
    texts = [b.decode("utf-8", errors="replace") for b in raw]
    if texts and texts[0].startswith("\ufeff"):
        texts[0] = texts[0][1:]
    return sum(1 for s in texts if s.strip())
