#!/usr/bin/env python3
"""Regenerate the table's device applicability from both revisions of the APT spec:

- dissector/msgs/90_devices.apt: the "Messages Applicable to …" lists at the start of each
  revision, one `devices` block per list;
- dissector/msgs/92_devices_sections.apt: each message section's own sentence ("This message is
  applicable only to KST101, KDC101 and KBD101 units"), one `section` block per sentence, naming
  the messages of the section it stands in.

Usage: dissector/tools/extract_devices.py ../shared/spec/apt-host-controller-protocol.txt \\
           ../shared/spec/apt-host-controller-protocol-2025-12-09.txt

A model implements a message when either source names it (FORMAT.md). The lists carry typos
(0x210 for 0x2100, REQ_PZSTATUSUPDATE 0x0661): a listed name is taken as the table spells it when
it exists, else the listed id is looked up; what was resolved so, and what could not be resolved,
is written as a comment beside the block. It prints, for the README's Devices section, where the
sections name a model that its lists leave out.
"""
import glob
import os
import re
import sys

here = os.path.dirname(os.path.abspath(__file__))
msgs_dir = os.path.join(here, "..", "msgs")

by_name, by_id = {}, {}
for f in sorted(glob.glob(os.path.join(msgs_dir, "*.apt"))):
    for l in open(f, encoding="utf-8"):
        m = re.match(r"\s*msg\s+0x([0-9A-Fa-f]{4})\s+(\S+)", l)
        if m:
            by_name[m.group(2)] = int(m.group(1), 16)
            by_id[int(m.group(1), 16)] = m.group(2)


def read(path):
    text = open(path, encoding="utf-8", errors="replace").read()
    return text.replace("\r", "\n").replace("\f", "\n").split("\n")


def revision(lines):
    head = " ".join(lines[:200])
    return "2025" if re.search(r"December\s+2025", head) else "Issue 23"


def resolve(raw_name, mid, notes):
    """The table's name for a spec entry (`MOT SET X` or `MOT_SET_X`, with its id if given)."""
    tokens = [t for t in re.split(r"[\s_]+", raw_name) if t]
    for name in ("_".join(tokens), "".join(tokens)):
        if name in by_name:
            if mid is not None and by_name[name] != mid:
                notes.append(f"{name} listed as 0x{mid:04X} (table: 0x{by_name[name]:04X})")
            return name
    if mid is not None and mid in by_id:
        notes.append(f"{'_'.join(tokens)} 0x{mid:04X} listed; taken as {by_id[mid]}")
        return by_id[mid]
    notes.append(f"UNRESOLVED {'_'.join(tokens)}" + (f" 0x{mid:04X}" if mid is not None else ""))
    return None


def models(title):
    t = re.sub(r"\((?:Continued|continued)\)", "", title)
    t = re.sub(r"\b(Series|Only)\b", "", t)
    parts = re.split(r",|\band\b", t)
    return [p.strip() for p in parts if p.strip()]


def lists(lines, rev):
    """The "Messages Applicable to …" lists at the start of a revision."""
    head = re.compile(r"^\s*Messages Applicable (?:Only )?to (.*?)\s*$")
    entry = re.compile(r"MGMSG[ _]+([A-Za-z0-9_ ]+?)[:;]?\s+0[xX]([0-9A-Fa-f]+)\b")
    blocks, cur = [], None
    for i, l in enumerate(lines, 1):
        if l.strip().startswith("Contents") and blocks:
            break
        if l.strip() == "Introduction" and blocks:
            break
        h = head.match(l)
        if h and "...." not in l:
            title = re.sub(r"\s+\d+$", "", h.group(1).strip())
            cur = {"line": i, "title": title, "msgs": [], "notes": [], "rev": rev}
            blocks.append(cur)
            continue
        if "Sub-Messages Applicable" in l:
            cur = None  # sub-message lists: the decoder needs no per-device sub ids
            continue
        if cur is None:
            continue
        e = entry.search(l)
        if not e:
            continue
        got = resolve(e.group(1), int(e.group(2), 16), cur["notes"])
        if got and got not in cur["msgs"]:
            cur["msgs"].append(got)
        if i > 3000:
            break
    return [b for b in blocks if b["msgs"]]


# A section heading line: message names, with or without their ids (after each name, or all
# after the names), nothing else (index and list entries end in a page number: not headings).
NAME = r"MGMSG[ _]+[A-Z0-9_ ]*?[A-Z0-9]"
ID = r"0[xX][0-9A-Fa-f]{4}"
HEADING = re.compile(rf"(?:{NAME}(?:\s*[:;]?\s*{ID})?\s*)+(?:{ID}\s*)*")
TOKEN = re.compile(rf"MGMSG[ _]+([A-Z0-9_ ]*?[A-Z0-9])(?=\s*(?:MGMSG|0[xX]|[:;]|$))|{ID}")
# A sentence counts for the section whose heading it follows within this many lines.
NEAR = 6


def heading_entries(line):
    """(name, id or None) of each message a heading line names."""
    names, ids = [], []
    for t in TOKEN.finditer(line):
        if t.group(1):
            names.append(t.group(1))
        else:
            ids.append(int(t.group(0), 16))
    if len(ids) == len(names):
        return list(zip(names, ids))
    if not names:
        return [(by_id.get(i, f"0x{i:04X}"), i) for i in ids]
    return [(n, None) for n in names]


SENTENCE = re.compile(
    r"^(?:note\.\s*)?(?:(?:this|these)\s+(?:message|messages|method)\s+(?:is|are)\s+)?"
    r"applicable\s+only\s+to\s+(.*)$",
    re.I,
)
# Family names a sentence uses for its models.
ALIASES = {"TNA T-Cube": "TNA001", "KNA K-Cube": "KNA101"}
MODEL = re.compile(r"\b(MMR|CT1P|[A-Z]{2,4}\d{2,4}[A-Za-z0-9]*|[A-Z]{3}\d{2}x|[A-Z]{3}x{3})\b")


def sentence_models(text):
    for k, v in ALIASES.items():
        text = text.replace(k, v)
    found = []
    for m in MODEL.findall(text):
        m = re.sub(r"-.*$", "", m)
        if m not in found:
            found.append(m)
    return found


def sections(lines, rev, start):
    """Each applicability sentence of a message section, with the section's messages."""
    blocks = []
    group, notes, in_heading, since = [], [], False, 0
    i = start
    while i < len(lines):
        l = lines[i].strip()
        i += 1
        if not l:
            continue
        if HEADING.fullmatch(l) or (re.fullmatch(ID, l) and in_heading):
            if not in_heading:
                group, notes = [], []
            in_heading, since = True, 0
            for name, mid in heading_entries(l):
                got = resolve(name, mid, notes)
                if got and got not in group:
                    group.append(got)
            continue
        in_heading = False
        since += 1
        if "sub-message" in l.lower() or "sub message" in l.lower():
            continue
        s = SENTENCE.match(l)
        following = "FOLLOWING CONTROLLERS" in l.upper()
        if not (s or following) or not group or since > NEAR:
            continue
        text = l
        # The sentence goes on over the next lines (a list of controllers, a wrapped line).
        j = i
        while j < len(lines) and len(text) < 400:
            nxt = lines[j].strip()
            if not nxt or nxt.startswith("Function") or nxt.startswith("Note"):
                break
            if not following and re.search(r"(units|UNITS|\.)\s*$", text):
                break
            text += " " + nxt
            j += 1
        found = sentence_models(text)
        if found:
            blocks.append(
                {"line": i, "text": re.sub(r"\s+", " ", text)[:160], "models": found,
                 "msgs": list(group), "notes": list(notes), "rev": rev}
            )
    return blocks


def write(path, header, blocks, keyword, title):
    out = header + [""]
    for b in blocks:
        out.append(f"{keyword} {' '.join(b['models'])}  # {b['rev']} line {b['line']}: {title(b)}")
        for n in b["notes"]:
            out.append(f"  # {n}")
        row = "  msgs"
        for m in b["msgs"]:
            if len(row) + 1 + len(m) > 100:
                out.append(row)
                row = "  msgs"
            row += " " + m
        out.append(row)
        out.append("")
    open(os.path.join(msgs_dir, path), "w", encoding="utf-8").write("\n".join(out))


list_blocks, section_blocks = [], []
for spec in sys.argv[1:]:
    lines = read(spec)
    rev = revision(lines)
    found = lists(lines, rev)
    for b in found:
        b["models"] = models(b["title"])
    list_blocks += found
    last = max(b["line"] for b in found)
    section_blocks += sections(lines, rev, last + 1)

write(
    "90_devices.apt",
    [
        "# Which messages each controller implements: the \"Messages Applicable to …\" lists at the start",
        "# of each revision of the spec (Issue 23 and 2025), one `devices` block per list (FORMAT.md).",
        "# GENERATED by dissector/tools/extract_devices.py from the spec; do not edit by hand.",
    ],
    list_blocks,
    "devices",
    lambda b: b["title"],
)
write(
    "92_devices_sections.apt",
    [
        "# What each message's own section says it applies to (\"This message is applicable only to …\"),",
        "# in both revisions of the spec: one `section` block per sentence, naming the messages of the",
        "# section it stands in (FORMAT.md). A model takes a message when its lists or a section name it.",
        "# GENERATED by dissector/tools/extract_devices.py from the spec; do not edit by hand.",
    ],
    section_blocks,
    "section",
    lambda b: b["text"],
)


def matches(pattern, model):
    return len(pattern) == len(model) and all(
        p == "x" or p.upper() == c.upper() for p, c in zip(pattern, model)
    )


# Where the sources disagree: a section names a model (one that has lists) for a message none of
# the model's lists name.
listed = {}
for b in list_blocks:
    for m in b["models"]:
        listed.setdefault(m, set()).update(b["msgs"])
rows = {}
for b in section_blocks:
    for model in b["models"]:
        has = [p for p in listed if matches(p, model) or matches(model, p)]
        if not has:
            continue
        missing = [m for m in b["msgs"] if not any(m in listed[p] for p in has)]
        if missing:
            rows.setdefault((model, b["rev"], b["line"]), []).extend(missing)
for (model, rev, line), msgs in sorted(rows.items()):
    print(f"| {model} | {', '.join(msgs)} | {rev} line {line} |")
