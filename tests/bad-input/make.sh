#!/usr/bin/env bash
# Regenerates the bad-input catalogue: one small file per kind of damage, built from the message
# table with `aptscope encode` (hex, then bytes with xxd), turned into captures with
# `aptscope convert`, then damaged with head/dd/python3. What `aptscope decode --json` reports
# for each file is in expected.txt, checked by tests/bad_input.rs.
#
#   tests/bad-input/make.sh [path/to/aptscope]
set -euo pipefail
cd "$(dirname "$0")"
A=${1:-../../target/debug/aptscope}
A=$(cd "$(dirname "$A")" && pwd)/$(basename "$A")
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
e() { "$A" encode "$@"; }
bin() { xxd -r -p; }

# Frames that ask for no reply, so no `no_reply` records join the diagnostics under test.
ident() { e MOD_IDENTIFY chan_ident=CH1; }                       # 6 bytes
status() { e MOT_GET_DCSTATUSUPDATE chan_ident=CH1 position="$1" velocity=120 status_bits='MOTOR_CONNECTED|ENABLED'; }  # 20 bytes

# --- APT byte streams ----------------------------------------------------------------------

# The stream ends 10 bytes into a 20-byte status update (at 6): truncated, at 6 + 10 = 16.
{ ident; status 1000; } | bin | head -c 16 > truncated-frame.bin

# 6 bytes that start no header, then two frames: garbage at 0.
{ echo "ff 00 55 aa 13 37"; ident; status 1000; } | bin > garbage-prefix.bin

# A frame, 5 bytes of garbage (at 6), a frame.
{ ident; echo "de ad be ef 00"; status 2000; } | bin > garbage-middle.bin

# Two frames (26 bytes), then 8 bytes of garbage: 3 that start no header (at 26), and the last
# 5, too few for a header, as trailing bytes (at 29).
{ ident; status 3000; echo "ee ee ee ee ee ee ee ee"; } | bin > garbage-suffix.bin

# MOT_MOVE_ABSOLUTE to bay1 claiming 0xFFFF data bytes (at 6): its 6 header bytes are skipped.
{ ident; echo "53 04 ff ff a2 01"; status 4000; } | bin > absurd-length.bin

# MOT_GET_DCSTATUSUPDATE with 10 data bytes (it has 14): length_mismatch at its length field (8).
{ ident; echo "91 04 0a 00 81 50 01 00 e8 03 00 00 78 00 00 00"; status 5000; } | bin > wrong-length.bin

# Message id 0xEEEE between known addresses (at 6).
{ ident; echo "ee ee 02 00 d0 01 12 34"; status 6000; } | bin > unknown-id.bin

# A status update from source 0x77, no address of the spec (source byte at 6 + 5 = 11).
{ ident; e MOT_GET_DCSTATUSUPDATE chan_ident=CH1 position=7000 velocity=120 status_bits=ENABLED --source 0x77; } | bin > unknown-address.bin

# MOD_IDENTIFY (header-only) with the 0x80 data flag and 2 data bytes (at 6; flag byte at 10).
{ ident; echo "23 02 02 00 d0 01 01 00"; status 8000; } | bin > header-only-with-data.bin

# --- Elliptec --------------------------------------------------------------------------------

# A move whose data has a Z (at 3 + 35 + 7 = 45), answered as usual.
{
  printf '0in'; printf '0IN0E1140028420200117016800023000\r\n'
  printf '0ma0000ZC00'; printf '0PO00008C00\r\n'
} > ell-bad-data-char.txt

# A position reply without CR LF (ends at 3 + 35 + 3 + 11 = 52) before the next command.
{
  printf '0in'; printf '0IN0E1140028420200117016800023000\r\n'
  printf '0gp'; printf '0PO00008C00'
  printf '0gs'; printf '0GS00\r\n'
} > ell-missing-crlf.txt

# --- Capture files ---------------------------------------------------------------------------

# Five chunks with times, in hex columns (one chunk per line), for `aptscope convert`.
{
  i=0
  for f in "$(ident)" "$(status 100)" "$(status 200)" "$(status 300)" "$(ident)"; do
    i=$((i + 1))
    echo "0.00${i}000 $f"
  done
} > "$tmp/session.txt"
"$A" convert "$tmp/session.txt" "$tmp/session.pcapng" 2>/dev/null
"$A" convert "$tmp/session.txt" "$tmp/session.pcap" 2>/dev/null
"$A" convert "$tmp/session.txt" "$tmp/session.mcap" 2>/dev/null

# pcapng cut 10 bytes into its fourth Enhanced Packet Block (type 6; blocks are type, length, …).
python3 - "$tmp/session.pcapng" truncated-block.pcapng <<'PY'
import struct, sys
d = open(sys.argv[1], "rb").read()
at, epb = 0, 0
while at < len(d):
    t, n = struct.unpack_from("<II", d, at)
    if t == 6:
        epb += 1
        if epb == 4:
            break
    at += n
open(sys.argv[2], "wb").write(d[: at + 10])
PY

# pcap with the first byte of its magic changed: no longer a pcap (read as raw bytes).
cp "$tmp/session.pcap" bad-magic.pcap
printf '\x00' | dd of=bad-magic.pcap bs=1 seek=0 conv=notrunc status=none

# pcap whose link type (bytes 20..23 of the file header) is 1, Ethernet.
cp "$tmp/session.pcap" unknown-linktype.pcap
printf '\x01\x00\x00\x00' | dd of=unknown-linktype.pcap bs=1 seek=20 conv=notrunc status=none

# The usbmon sample (big-endian pcap, link type 220: 64-byte usbmon headers) with its first record
# (at 24) cut to 20 bytes, shorter than a usbmon header; the other records follow unchanged.
python3 - ../../samples/kdc101-session.usbmon.pcap short-usbmon.pcap <<'PY'
import struct, sys
d = open(sys.argv[1], "rb").read()
sec, usec, cap, orig = struct.unpack_from(">IIII", d, 24)
short = struct.pack(">IIII", sec, usec, 20, 20) + d[40:60]
open(sys.argv[2], "wb").write(d[:24] + short + d[40 + cap :])
PY

# MCAP records: opcode (1 byte), length (u64), body. The first Chunk (opcode 6) gets a wrong
# uncompressed CRC (body offset 24: after start time, end time, uncompressed size).
python3 - "$tmp/session.mcap" bad-chunk-crc.mcap truncated.mcap <<'PY'
import struct, sys
d = bytearray(open(sys.argv[1], "rb").read())
at, chunk, data_end = 8, None, None
while at + 9 <= len(d):
    op, n = d[at], struct.unpack_from("<Q", d, at + 1)[0]
    if op == 0x06 and chunk is None:
        chunk = at
    if op == 0x0F:
        data_end = at
        break
    at += 9 + n
bad = bytearray(d)
bad[chunk + 9 + 24] ^= 0xFF
open(sys.argv[2], "wb").write(bad)
# Cut at the Data End record: no summary, no footer, no closing magic.
open(sys.argv[3], "wb").write(d[:data_end])
PY

# --- Any input -------------------------------------------------------------------------------

: > empty.bin
python3 -c 'import random, sys; sys.stdout.buffer.write(random.Random(1234).randbytes(512))' > random.bin
ls -l
