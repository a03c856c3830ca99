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
du -sh "$C"
