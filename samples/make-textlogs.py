#!/usr/bin/env python3
"""Regenerate the serial-tool logs of the KDC101 session (samples/kdc101-session.hex) as the
tools themselves print them, so the text-log readers can be tested against one known stream:

  kdc101-session.socat.log        socat -d -d -x -v PTY,link=/tmp/kdc101,rawer \
                                        /dev/ttyUSB0,rawer,b115200,crtscts=1   (stderr)
  kdc101-session.jpnevulator.txt  jpnevulator --read --pass --pty --tty /dev/ttyUSB0 \
                                        --timing-print --ascii
  kdc101-session.interceptty.log  interceptty -T -s 'ispeed 115200 ospeed 115200' \
                                        /dev/ttyUSB0 /tmp/kdc101
  kdc101-session.xxd.txt          xxd kdc101-session.bin

The host program talks to the controller through the pty (socat's left address, jpnevulator's
--pty, interceptty's front device). Each frame is one read, except the 90-byte HW_GET_INFO
reply, which arrives as a full 62-byte FTDI packet and, 16 ms later (latency timer), the
remaining 28 bytes. Times: the session starts at 2024-05-01 12:00:00 (local time), status
updates come every 100 ms, homing takes 2 s.

The formatting follows each tool's source: socat's xiotransfer() hex dump, jpnevulator's
headerWrite()/asciiWrite(), interceptty's dumpbuff() with char_repr(), xxd's default layout.
Standard library only. Usage: python3 samples/make-textlogs.py
"""

import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
DATE = "2024/05/01"
JDATE = "2024-05-01"

# Messages of the session that come from the controller; every other one comes from the host.
D2H = {
    0x0006: "HW_GET_INFO",
    0x0212: "MOD_GET_CHANENABLESTATE",
    0x0444: "MOT_MOVE_HOMED",
    0x0464: "MOT_MOVE_COMPLETED",
    0x0491: "MOT_GET_DCSTATUSUPDATE",
}

# When each frame (in file order) starts, in microseconds after 12:00:00.
FRAME_US = [
    0,  # HW_REQ_INFO
    11234,  # HW_GET_INFO (62 bytes now, 28 bytes at 26871)
    150412,  # MOD_SET_CHANENABLESTATE
    250733,  # MOD_REQ_CHANENABLESTATE
    262109,  # MOD_GET_CHANENABLESTATE
    400518,  # HW_START_UPDATEMSGS
    500247,  # MOT_MOVE_HOME
    600391, 700455, 800502, 900611,  # status updates while homing
    2512378,  # MOT_MOVE_HOMED (2 s after the home command)
    2700164,  # MOT_MOVE_ABSOLUTE
    2800227, 2900301, 3000354, 3100398, 3200445,  # status updates while moving
    3251087,  # MOT_MOVE_COMPLETED
    3500932,  # HW_STOP_UPDATEMSGS
]
SPLIT = {1: (62, 26871)}  # frame index -> (bytes in the first read, time of the second read)


def frames():
    out = []
    with open(os.path.join(HERE, "kdc101-session.hex")) as f:
        for line in f:
            if line.strip():
                out.append(bytes.fromhex(line))
    return out


def reads():
    """(microseconds, 'h2d'|'d2h', bytes) for each read, in time order."""
    fr = frames()
    assert len(fr) == len(FRAME_US), (len(fr), len(FRAME_US))
    out = []
    for i, (frame, us) in enumerate(zip(fr, FRAME_US)):
        msgid = frame[0] | frame[1] << 8
        d = "d2h" if msgid in D2H else "h2d"
        if i in SPLIT:
            n, us2 = SPLIT[i]
            out.append((us, d, frame[:n]))
            out.append((us2, d, frame[n:]))
        else:
            out.append((us, d, frame))
    assert [r[0] for r in out] == sorted(r[0] for r in out)
    return out


def clock(us):
    s, us = divmod(us, 1_000_000)
    return 12, s // 60, s % 60, us


def isprint(c):
    return 0x20 <= c < 0x7F


def socat(rd):
    # socat -d -d notices go to stderr too, before the data.
    out = [
        f"{DATE} 11:59:58 socat[48213] N PTY is /dev/pts/3\n",
        f"{DATE} 11:59:58 socat[48213] N opening character device \"/dev/ttyUSB0\" for reading and writing\n",
        f"{DATE} 11:59:58 socat[48213] N starting data transfer loop with FDs [5,5] and [7,7]\n",
    ]
    num = {"h2d": 0, "d2h": 0}
    for us, d, data in rd:
        h, m, s, frac = clock(us)
        prefix = "> " if d == "h2d" else "< "  # host (pty) is socat's left address
        out.append(f"{prefix}{DATE} {h:02d}:{m:02d}:{s:02d}.{frac:06d}  length={len(data)} "
                   f"from={num[d]} to={num[d] + len(data) - 1}\n")
        num[d] += len(data)
        i = 0
        while i < len(data):  # xiotransfer(): 16 a line, a line also ends after '\n'
            line = b""
            while len(line) < 16 and i < len(data):
                line += data[i:i + 1]
                i += 1
                if line[-1] == 0x0A:
                    break
            hexs = "".join(f" {c:02x}" for c in line) + "   " * (16 - len(line)) + "  "
            asc = "".join(chr(c) if isprint(c) else "." for c in line)
            out.append(hexs + asc + "\n")
        out.append("--\n")
    return "".join(out).encode()


def jpnevulator(rd):
    width, delta = 16, 100_000
    name = {"h2d": "/dev/pts/3", "d2h": "/dev/ttyUSB0"}  # --pty first, then --tty
    out = []
    last_name, last_us = None, None
    line = []  # bytes on the current output line (bytesWritten / ascii[])

    def ascii_write(fill):
        if line:
            pad = "   " * (width - len(line)) if fill else ""
            out.append(pad + "\t" + "".join(chr(c) if isprint(c) else "." for c in line) + "\n")
            line.clear()

    for us, d, data in rd:
        if name[d] != last_name or last_us is None or us - last_us > delta:
            ascii_write(True)
            h, m, s, frac = clock(us)
            out.append(f"{JDATE} {h:02d}:{m:02d}:{s:02d}.{frac:06d}: {name[d]}\n")
            last_name = name[d]
        last_us = us
        for c in data:
            if len(line) >= width:
                ascii_write(False)
            elif line:
                out.append(" ")
            out.append(f"{c:02X}")
            line.append(c)
    ascii_write(True)
    return "".join(out).encode()


CTRL = ["NUL", "SOH", "STX", "ETX", "EOT", "ENQ", "ACK", "BEL", "BS", "TAB", "LF", "VT", "FF",
        "CR", "SO", "SI", "DLE", "DC1", "DC2", "DC3", "DC4", "NAK", "SYN", "ETB", "CAN", "EM",
        "SUB", "ESC", "FS", "GS", "RS", "US"]


def char_repr(c):
    if c < 32:
        return f"[{CTRL[c]}]".encode()
    if c == 32:
        return b"' '"
    if c == 127:
        return b"[DEL]"
    return bytes([c])  # printed with %c: bytes >= 0x80 go out as they are


def interceptty(rd):
    out = []
    for us, d, data in rd:
        h, m, s, frac = clock(us)
        stamp = f"[{h:02d}:{m:02d} {s:02d}.{frac:06d}]".encode()  # strftime("%H:%M %S")
        for i, c in enumerate(data):
            out.append(stamp if i == 0 else b" " * len(stamp))
            out.append(b"> \t" if d == "d2h" else b"< ")  # '>' = from the back (real) device
            out.append(f"0x{c:02x} (".encode() + char_repr(c) + b")\n")
    return b"".join(out)


def xxd(data):
    out = []
    for off in range(0, len(data), 16):
        line = data[off:off + 16]
        groups = " ".join(line[i:i + 2].hex() for i in range(0, len(line), 2))
        asc = "".join(chr(c) if isprint(c) else "." for c in line)
        out.append(f"{off:08x}: {groups:<39}  {asc}\n")
    return "".join(out).encode()


def main():
    rd = reads()
    with open(os.path.join(HERE, "kdc101-session.bin"), "rb") as f:
        binary = f.read()
    assert b"".join(frames()) == binary, "kdc101-session.bin is not kdc101-session.hex"
    files = {
        "kdc101-session.socat.log": socat(rd),
        "kdc101-session.jpnevulator.txt": jpnevulator(rd),
        "kdc101-session.interceptty.log": interceptty(rd),
        "kdc101-session.xxd.txt": xxd(binary),
    }
    # Cross-check against the real xxd when there is one.
    try:
        real = subprocess.run(["xxd", os.path.join(HERE, "kdc101-session.bin")],
                              capture_output=True, check=True).stdout
        assert real == files["kdc101-session.xxd.txt"], "xxd layout differs from the real xxd"
    except FileNotFoundError:
        print("xxd not found: layout not cross-checked", file=sys.stderr)
    for name, data in files.items():
        with open(os.path.join(HERE, name), "wb") as f:
            f.write(data)


if __name__ == "__main__":
    main()
