"""Reads a .dfq file with aqdefreader (PyPI), a reader Sheen does not own,
and prints what it found as JSON for the Rust tests to compare.

Usage: python3 tests/aqdef_read.py FILE.dfq

aqdefreader reads parts (K1xxx), characteristics (K2xxx) and each value's
K0001 (value), K0002 (attribute) and K0004 (date/time). It does not keep
the value-level text fields (K0006, K0014 part ID and the others): those
are read here from the file's own lines, per characteristic, in order.
It parses K0004 with dateutil, month first: a day of 12 or less reads with
day and month swapped, so the tests use days after the 12th where they
compare times through it.
"""

import contextlib
import io
import json
import sys

import aqdefreader


def number(value):
    if isinstance(value, (int, float)):
        return float(value)
    try:
        return float(str(value).replace(",", "."))
    except ValueError:
        return value


def main(path):
    with contextlib.redirect_stdout(io.StringIO()):
        dfq = aqdefreader.read_dfq_file(path)
    # The value-level text fields, by characteristic index, in file order.
    texts = {}
    with open(path, "rb") as f:
        for raw in f.read().decode("latin-1").split("\r\n"):
            if raw[:5] in ("K0006", "K0014", "K0009") and "/" in raw[:7]:
                code, _, rest = raw.partition(" ")
                key, index = code.split("/")
                texts.setdefault(int(index), {}).setdefault(key, []).append(rest)
    parts = []
    index = 0
    for part in dfq.get_parts():
        characteristics = []
        for c in part.get_characteristics():
            index += 1
            fields = {k: c.get_data(k) for k in c.get_data_keys()}
            characteristics.append(
                {
                    "index": index,
                    "number": str(fields.get("K2001")),
                    "description": fields.get("K2002"),
                    "nominal": number(fields["K2101"]) if "K2101" in fields else None,
                    "lower": number(fields["K2110"]) if "K2110" in fields else None,
                    "upper": number(fields["K2111"]) if "K2111" in fields else None,
                    "unit": fields.get("K2142"),
                    "values": [
                        {
                            "value": number(m.value),
                            "attribute": int(m.attribute) if m.attribute is not None else None,
                            "time": m.datetime.isoformat() if m.datetime else None,
                        }
                        for m in c.get_measurements()
                    ],
                    "texts": texts.get(index, {}),
                }
            )
        parts.append({"part_number": str(part.get_part_no()), "characteristics": characteristics})
    json.dump({"parts": parts}, sys.stdout)


if __name__ == "__main__":
    main(sys.argv[1])
