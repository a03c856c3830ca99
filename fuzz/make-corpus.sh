#!/usr/bin/env bash
# Seeds the fuzz corpora from samples/ and tests/bad-input/ (small files only). Each target's
# input starts with a few control bytes (chunking, flags: see the target's header comment), so
# every seed is a sample with such a prefix. Files are named seed-*; what libFuzzer finds while
# running goes to fuzz/work/ (git-ignored). Usage: fuzz/make-corpus.sh
set -euo pipefail
cd "$(dirname "$0")/.."
S=samples
B=tests/bad-input
C=fuzz/corpus
rm -f "$C"/*/seed-*
mkdir -p "$C"/{apt_framer,ell_framer,pcap_reader,mcap_reader,textlog_reader,decode_pipeline,filter_parse,encode_roundtrip}
mkdir -p "$C"/{ell_encode,units,usb_unwrap,follow_reader,dataset_rows,arrow_pool,tui_view}

# seed TARGET NAME PREFIX_HEX FILE
seed() { { printf '%s' "$3" | xxd -r -p; cat "$4"; } > "$C/$1/seed-$2"; }

apt_bins=("$S/kdc101-session.bin" "$S/damaged.bin")
xxd -r -p "$S/bsc203-rack.hex" > /tmp/aptscope-bsc203.bin
apt_bins+=(/tmp/aptscope-bsc203.bin)
for f in "${apt_bins[@]}"; do
  n=$(basename "$f" .bin)
  seed apt_framer "$n-whole" 000000 "$f"
  seed apt_framer "$n-bytewise" 010080 "$f"
  seed apt_framer "$n-chunks" 0d0581 "$f"
done
seed ell_framer elliptec-bus-whole 000000 "$S/elliptec-bus.txt"
seed ell_framer elliptec-bus-bytewise 010080 "$S/elliptec-bus.txt"
seed ell_framer elliptec-bus-chunks 070381 "$S/elliptec-bus.txt"

for f in kdc101-session.pcap kdc101-session.pcapng kdc101-session.usbmon.pcap; do
  seed pcap_reader "$f" 000000 "$S/$f"
  seed pcap_reader "$f-short" 1f0300 "$S/$f"
done
seed pcap_reader usbmon-device 00000f "$S/kdc101-session.usbmon.pcap"
[ -f "$S/kdc101-session.usbpcap.pcap" ] && seed pcap_reader usbpcap 000000 "$S/kdc101-session.usbpcap.pcap"
seed mcap_reader kdc101-session.mcap 000001 "$S/kdc101-session.mcap"
seed mcap_reader kdc101-session.mcap-short 3f0700 "$S/kdc101-session.mcap"

# textlog: the first byte picks the reader (TextFormat::ALL order).
seed textlog_reader socat 00000000 "$S/kdc101-session.socat.log"
seed textlog_reader jpnevulator 01000000 "$S/kdc101-session.jpnevulator.txt"
head -c 3000 "$S/kdc101-session.interceptty.log" > /tmp/aptscope-icpt.log
seed textlog_reader interceptty 020d02 /tmp/aptscope-icpt.log
seed textlog_reader xxd 030000 "$S/kdc101-session.xxd.txt"
xxd -r -p "$S/kdc101-session.hex" | hexdump -C > /tmp/aptscope-hd.txt
seed textlog_reader hexdump 040000 /tmp/aptscope-hd.txt
seed textlog_reader hexcols 050000 "$S/kdc101-session.hex"

# decode_pipeline: flags byte (proto auto/apt/elliptec, hex, raw) then a file of any format.
for f in "$S"/*; do
  [ -f "$f" ] || continue
  case "$f" in *.sh|*.py|*.interceptty.log) continue ;; esac
  seed decode_pipeline "$(basename "$f")" 00 "$f"
done
seed decode_pipeline elliptec-forced 02 "$S/elliptec-bus.txt"
seed decode_pipeline damaged-hex 04 "$S/damaged.hex"
# The bad-input catalogue, for the pipeline and for the reader of each capture format.
for f in "$B"/*; do
  n=$(basename "$f")
  case "$n" in make.sh | expected.txt) continue ;; esac
  [ "$(stat -c %s "$f")" -le 16384 ] || continue
  seed decode_pipeline "bad-$n" 00 "$f"
  case "$n" in
    *.pcap | *.pcapng) seed pcap_reader "bad-$n" 000000 "$f" ;;
    *.mcap) seed mcap_reader "bad-$n" 000001 "$f" ;;
    ell-*) seed ell_framer "bad-$n" 000000 "$f" ;;
    *.bin) seed apt_framer "bad-$n" 000000 "$f" ;;
  esac
done

# filter_parse: the README's filters and the filter tests' vocabulary.
i=0
while IFS= read -r line; do
  i=$((i + 1))
  printf '%s' "$line" > "$C/filter_parse/seed-$i"
done <<'FILTERS'
apt.name ~ "^MOT_MOVE_" && apt.dst == bay2
apt.fields.status_bits contains HOMED
latency > 50ms || unpaired || diag
ell.addr == "A" && ell.cmd == ma
dir == host && !(apt.name ~ MOT) && apt.chan
apt.msgid in {0x0491 1169, 5}
latency >= 0.5s && latency < 2000
ts_ns < 1764000000100000000 or not paired
ell.phys.position >= 45 and ell.module.model == ELL17
diag.kind == "truncated" || diag.offset == 65
(((type == garbage)))
apt.fields.position != -5 && apt.fields.velocity <= 1.5e3
ell.cmd matches "(?-i)^g" && ell.text contains "\r"
apt.name == 
FILTERS

# encode_roundtrip: form index (2 bytes), dst, src, then value bytes.
seed encode_roundtrip move-absolute 01005001 /dev/null
printf '\x00\x10\x50\x01\x00\x01\x00\x00\x00\x00\x00\x00\x00\x81\x40\x0d\x03\x00\x00\x00\x00\x00' > "$C/encode_roundtrip/seed-values"
printf '\x00\x20\x21\x01\x03\x05CH1xx\x83\x04-100\x03\x0a0x7fffffff' > "$C/encode_roundtrip/seed-text"
head -c 200 "$S/kdc101-session.bin" > "$C/encode_roundtrip/seed-bytes"

# ell_encode: command row, address, then per field: how (2: given), kind (0: decimal), 8 bytes.
for row in 0 5 12 20 31 40; do
  printf "$(printf '\\x%02x' "$row")"'\x02\x02\x00\x05\x00\x00\x00\x00\x00\x00\x00\x02\x01\x10\x00\x00\x00\x00\x00\x00\x00' \
    > "$C/ell_encode/seed-row-$row"
done
printf '\x07\x8a\x02\x03\x00\x02\x03\x01ma' > "$C/ell_encode/seed-by-name"
printf '\x09\x03\x02\x04\x00\x02\x06\x05hello\x01\x03\x02' > "$C/ell_encode/seed-names"

# units: flags (1 stage, 2 scale, 4 controller), counts and raw (f64 bits), then NUL-separated
# stage, scale, controller, model.
f64() { python3 -c "import struct,sys; sys.stdout.buffer.write(struct.pack('<d', float('$1')))"; }
useed() { { printf "$2"; f64 "$3"; f64 "$4"; printf '%s\0%s\0%s\0%s' "$5" "$6" "$7" "$8"; } > "$C/units/seed-$1"; }
useed stage '\x01' 34554.96 20000 MTS25-Z8 "" "" KDC101
useed scale '\x26' 1919.64 -4500 "" 1919.64/deg KBD101 ""
useed controller '\x45' 0 772981 "" "" BSC203 BSC203
useed fixed '\x00' 1e-300 1e300 "" "" "" K10CR1/M
useed zst '\x05' nan inf ZST213 "" TDC001 TDC001

# usb_unwrap: mode 0/1 (serial chunks [dir, len, bytes] through synth_usbmon, 1: then flips),
# mode 2 (packets [linktype, len, cut, bytes] from the usbmon and USBPcap samples).
chunks() { python3 - "$1" <<'PY'
import sys
data = open(sys.argv[1], 'rb').read()[:1200]
out, i, d = bytearray(), 0, 0
while i < len(data):
    n = min(len(data) - i, 7 + (i * 13) % 90)
    out += bytes([d | 2 | (i % 7) << 2, n]) + data[i:i + n]
    i, d = i + n, d ^ 1
sys.stdout.buffer.write(out)
PY
}
{ printf '\x00\x00\x08'; chunks "$S/kdc101-session.bin"; } > "$C/usb_unwrap/seed-synth"
{ printf '\x00\x05\x40'; chunks "$S/kdc101-session.bin"; } > "$C/usb_unwrap/seed-synth-device"
{ printf '\x01\x00\x08'; chunks "$S/kdc101-session.bin"; printf '\x00\x00\x20\x01\x55\x90\x03\x07\x01\x02\x10'; } > "$C/usb_unwrap/seed-flips"
packets() { python3 - "$1" "$2" <<'PY'
import struct, sys
data, sel = open(sys.argv[1], 'rb').read(), int(sys.argv[2])
out, at = bytearray(), 24
while at + 16 <= len(data) and len(out) < 12000:
    incl, orig = struct.unpack_from('<II', data, at + 8)
    rec = data[at + 16:at + 16 + incl][:511]
    out += bytes([sel]) + struct.pack('<H', len(rec)) + bytes([min(255, orig - len(rec))]) + rec
    at += 16 + incl
sys.stdout.buffer.write(out)
PY
}
{ printf '\x02\x00\x00'; packets "$S/kdc101-session.usbmon.pcap" 1; } > "$C/usb_unwrap/seed-usbmon"
{ printf '\x02\x00\x00'; packets "$S/kdc101-session.usbpcap.pcap" 2; } > "$C/usb_unwrap/seed-usbpcap"

# follow_reader: flags (1: head first), head limit, then pieces [len/4, read_max, bytes].
pieces() { python3 - "$1" <<'PY'
import sys
data = open(sys.argv[1], 'rb').read()[:6000]
out, i = bytearray(), 0
while i < len(data):
    n = min(len(data) - i, 4 * (1 + (i * 7) % 60))
    out += bytes([n // 4, 1 + (i * 11) % 200]) + data[i:i + n - n % 4 if n >= 4 else i + n]
    i += n - n % 4 if n >= 4 else n
sys.stdout.buffer.write(out)
PY
}
for f in kdc101-session.pcap kdc101-session.mcap kdc101-session.socat.log elliptec-bus.txt; do
  { printf '\x01\x40'; pieces "$S/$f"; } > "$C/follow_reader/seed-$f"
done
{ printf '\x02\x00'; pieces "$S/kdc101-session.bin"; } > "$C/follow_reader/seed-raw"
# dataset_rows: the decode_pipeline seeds with a budget byte after the flags (5: row groups of
# 6 rows and 144 bytes).
for f in "$C"/decode_pipeline/seed-*; do
  { head -c 1 "$f"; printf '\x05'; tail -c +2 "$f"; } > "$C/dataset_rows/$(basename "$f")"
done

# arrow_pool: the same seeds with a budget byte (5), runs of 3 records and the last run in parts
# of 1 at least, on two threads (flags as given: a protocol byte of 0-2) and, for the samples,
# three threads keeping their batches in runs growing to a row group.
for f in "$C"/decode_pipeline/seed-*; do
  b=$(basename "$f")
  { head -c 1 "$f"; printf '\x05\x03\x01'; tail -c +2 "$f"; } > "$C/arrow_pool/$b"
  case "$b" in
    seed-bad-*) ;;
    *)
      p=$(head -c 1 "$f" | od -An -tu1 | tr -d ' ')
      # The first flags of 64 or more with the seed's protocol and a third thread.
      t=64
      while (( t % 3 != p % 3 || t / 3 % 2 == 0 )); do t=$((t + 1)); done
      { printf "\\x$(printf %02x "$t")\x05\x00\x01"; tail -c +2 "$f"; } > "$C/arrow_pool/$b-3threads"
      ;;
  esac
done

# tui_view: the decode_pipeline seeds with a screen size byte and 16 key bytes (indexes into
# the target's KEYS): browsing (j j Tab j Enter space Tab G PgDn ^u s q p q ? Esc) at 80x24;
# for the samples also a filter, a go-to and the stream keys (/ a p t Enter n : 9 Enter < > 1 2
# & t Esc); a few browse a 12x4 and a 160x48 screen. (Each seed draws 17 screens: about 80 ms
# in the debug build of `cargo test`.)
browse=00002400261b2403212a0a1108111227
filter=130d080c2606142d2616171819150c27
tseed() { { head -c 1 "$C/decode_pipeline/seed-$1"; printf '%s' "$3" | xxd -r -p; tail -c +2 "$C/decode_pipeline/seed-$1"; } > "$C/tui_view/seed-$1$2"; }
for f in "$C"/decode_pipeline/seed-*; do
  b=$(basename "$f")
  b=${b#seed-}
  tseed "$b" "" "00$browse"
  case "$b" in
    bad-*) ;;
    *) tseed "$b" -filter "00$filter" ;;
  esac
done
for b in kdc101-session.pcapng elliptec-bus.txt damaged.bin; do
  tseed "$b" -tiny "03$browse"
  tseed "$b" -large "01$browse"
done

# Inputs that once made a target fail (fuzz/artifacts-found/<target>/) are seeds of it too.
for d in fuzz/artifacts-found/*/; do
  t=$(basename "$d")
  for f in "$d"*; do
    cp "$f" "$C/$t/seed-found-$(basename "$f" .fuzz)"
  done
done
du -sh "$C"
