"""The Python half of bench/compare-python.sh: thorlabs-apt-protocol's Unpacker on a raw APT stream.

  compare_python.py check SAMPLE DUMP   decode SAMPLE with the Unpacker and compare, message by
                                        message, with aptscope's raw field values (DUMP: the
                                        NDJSON of `decode_file SAMPLE --dump`); exit 1 on a mismatch
  compare_python.py time FILE SECONDS RUNS [--cached-namedtuple]
                                        time Unpacker.feed() + iterating every message on a prefix
                                        of FILE sized to take about SECONDS per run (all of FILE
                                        if it is faster); prints JSON of the best of RUNS.
                                        --cached-namedtuple: the same with the Unpacker's
                                        per-message namedtuple class cached per message kind
                                        (it builds a new class for every message; this shows
                                        what the package's framing and parsing cost without it)
"""

import collections
import functools
import json
import sys
import time

from thorlabs_apt_protocol import Unpacker
from thorlabs_apt_protocol.parsing import _parse_pz_status_bits, _parse_status_bits

# Python field name -> aptscope field name, where they differ.
ALIAS = {
    "HW_GET_INFO": {"type": "hw_type"},
    "MOT_GET_VELPARAMS": {"min_velocity": "min_vel", "max_velocity": "max_vel"},
    "MOT_GET_JOGPARAMS": {
        "step_size": "jog_step_size",
        "min_velocity": "jog_min_vel",
        "acceleration": "jog_acceleration",
        "max_velocity": "jog_max_vel",
        "stop_mode": "jog_stop_mode",
    },
    "MOT_GET_LIMSWITCHPARAMS": {
        "cw_hardlimit": "cw_hard_limit",
        "ccw_hardlimit": "ccw_hard_limit",
        "cw_softlimit": "cw_soft_limit",
        "ccw_softlimit": "ccw_soft_limit",
    },
    "MOT_GET_DCPIDPARAMS": {"integral_limits": "integral_limit"},
    "MOT_GET_KCUBEMMIPARAMS": {
        "mode": "js_mode",
        "max_vel": "js_max_vel",
        "accn": "js_accn",
        "pre_set_pos1": "preset_pos1",
        "pre_set_pos2": "preset_pos2",
    },
    "PZ_GET_OUTPUTPOS": {"position": "position_sw"},
    "PZ_GET_PZSTATUSUPDATE": {"output_voltage": "op_voltage"},
}
PZ_STATUS = {"PZ_GET_PZSTATUSUPDATE", "PZ_GET_PZSTATUSBITS"}


def expected(name, key, fields):
    """What the Python field `key` should be, computed from aptscope's raw values; KeyError if
    aptscope has nothing to compare it with."""
    if key == "firmware_version":  # HW_GET_INFO: [major, interim, minor]
        return [fields["fw_major"], fields["fw_interim"], fields["fw_minor"]]
    if key == "enabled" and name == "MOD_GET_CHANENABLESTATE":
        return fields["enable_state"] == 1
    if key == "occupied":  # RACK_GET_BAYUSED
        return fields["bay_state"] == 1
    apt_key = ALIAS.get(name, {}).get(key, key)
    if apt_key in fields:
        return fields[apt_key]
    # Status bits, which the Unpacker expands into booleans: decode aptscope's raw word with the
    # package's own bit table.
    bits = (_parse_pz_status_bits if name in PZ_STATUS else _parse_status_bits)(
        fields["status_bits"]
    )
    return bits[key]


def same(py, apt):
    if isinstance(py, bytes):
        return py.rstrip(b"\0").decode("latin-1") == apt
    if isinstance(py, bool) or isinstance(apt, bool):
        return bool(py) == bool(apt) and type(py) is type(apt)
    return py == apt


def same_bits(py, apt):
    """Equal as 16- or 32-bit words: one side reads the field signed, the other unsigned."""
    if not (isinstance(py, int) and isinstance(apt, int)):
        return False
    return abs(py - apt) in (1 << 16, 1 << 32)


def check(sample_path, dump_path):
    data = open(sample_path, "rb").read()
    u = Unpacker()
    u.feed(data)
    py = [m._asdict() for m in u]
    apt = [json.loads(line) for line in open(dump_path)]
    problems = []
    if len(py) != len(apt):
        problems.append(f"message count: Unpacker {len(py)}, aptscope {len(apt)}")
    compared = 0
    signedness = {}
    unchecked = set()
    for i, (p, a) in enumerate(zip(py, apt)):
        name = a.get("name")
        if name is None or a.get("diag"):
            problems.append(f"#{i}: aptscope: {a}")
            continue
        if p["msg"].upper() != name:
            problems.append(f"#{i} at {a['offset']}: Unpacker {p['msg']}, aptscope {name}")
            continue
        for k, v in (("msgid", "msgid"), ("source", "src"), ("dest", "dst")):
            compared += 1
            if p[k] != a[v]:
                problems.append(f"#{i} {name}: {k} {p[k]} vs {a[v]}")
        for k, v in p.items():
            if k in ("msg", "msgid", "source", "dest"):
                continue
            try:
                e = expected(name, k, a["fields"])
            except KeyError:
                unchecked.add(f"{name}.{k}")
                continue
            compared += 1
            if same(v, e):
                continue
            if same_bits(v, e):
                key = f"{name}.{k}"
                signedness[key] = signedness.get(key, 0) + 1
                continue
            problems.append(f"#{i} {name}.{k}: Unpacker {v!r}, aptscope {e!r}")
    print(
        f"check: {len(data)} bytes: {len(py)} messages from the Unpacker, {len(apt)} from "
        f"aptscope; {len(set(m['name'] for m in apt))} kinds; {compared} values compared, "
        f"{len(problems)} mismatches"
    )
    if signedness:
        n = sum(signedness.values())
        print(
            f"check: {n} values with the same bits read signed by one side and unsigned by the "
            f"other: {', '.join(sorted(signedness))}"
        )
    if unchecked:
        print(f"check: fields aptscope has no counterpart for: {', '.join(sorted(unchecked))}")
    for p in problems[:20]:
        print(f"check: MISMATCH {p}")
    return 1 if problems else 0


def run(data):
    """One timed run: feed + iterate. Returns (messages, bytes decoded, seconds)."""
    u = Unpacker()
    t0 = time.perf_counter()
    u.feed(data)
    n = 0
    for _ in u:
        n += 1
    dt = time.perf_counter() - t0
    # A prefix may end inside a frame: those bytes were not decoded.
    left = len(u.buf) + len(u._file.read())
    return n, len(data) - left, dt


def timing(path, seconds, runs):
    data = open(path, "rb").read()
    n, b, dt = run(data[:50_000])  # calibration
    size = min(len(data), int(b / dt * seconds))
    prefix = data[:size]
    best = None
    for _ in range(runs):
        r = run(prefix)
        if best is None or r[2] < best[2]:
            best = r
    n, b, dt = best
    print(
        json.dumps(
            {
                "file_bytes": len(data),
                "bytes": b,
                "messages": n,
                "seconds": dt,
                "runs": runs,
                "mb_per_s": b / dt / 1e6,
                "msgs_per_s": n / dt,
            }
        )
    )


def cache_namedtuple():
    import thorlabs_apt_protocol.unpacker as unpacker

    make = functools.lru_cache(maxsize=None)(collections.namedtuple)
    unpacker.namedtuple = lambda name, keys: make(name, tuple(keys))


if __name__ == "__main__":
    if sys.argv[1] == "check":
        sys.exit(check(sys.argv[2], sys.argv[3]))
    elif sys.argv[1] == "time":
        if sys.argv[5:] == ["--cached-namedtuple"]:
            cache_namedtuple()
        timing(sys.argv[2], float(sys.argv[3]), int(sys.argv[4]))
    else:
        sys.exit(__doc__)
