#!/usr/bin/env bash
# Simulator speed (docs/simulators.md): N (default 10 000) request/reply pairs through the tap
# at 115 200 baud. A host writes MOT_REQ_VELPARAMS (6 bytes) N times as fast as the link takes
# them to `aptscope tap`, in front of `aptscope sim apt --model kdc101`, and reads the N
# MOT_GET_VELPARAMS (20 bytes each) back; the simulator paces its replies at the line's byte
# time, so the session lasts N × 20 bytes / 11 520 bytes/s at best. Checked: every reply byte
# arrived, in whole frames, and the tap's own check ("matches what was forwarded").
# Prints the session's duration, the replies per second and the simulator's CPU time.
# Usage: bench/sim-speed.sh [N] [PROFILE]   (PROFILE: debug (default) or release)
set -euo pipefail
cd "$(dirname "$0")/.."
n=${1:-10000}
profile=${2:-debug}
if [ "$profile" = release ]; then cargo build -q --release; else cargo build -q; fi
bin=target/$profile/aptscope
dir=$(mktemp -d)
trap 'kill $sim $tap 2>/dev/null || true; rm -rf "$dir"' EXIT
"$bin" sim apt --model kdc101 --pty "$dir/dev" >"$dir/sim.log" 2>&1 &
sim=$!
while [ ! -L "$dir/dev" ]; do sleep 0.05; done
"$bin" tap --device "$dir/dev" --link "$dir/host" -w "$dir/cap.pcapng" --quiet 2>"$dir/tap.log" &
tap=$!
while [ ! -L "$dir/host" ]; do sleep 0.05; done
python3 - "$dir/host" "$n" <<'PY'
import os, sys, time, termios, tty, select
link, n = sys.argv[1], int(sys.argv[2])
fd = os.open(link, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
tty.setraw(fd)
req = bytes.fromhex("140401005001")  # MOT_REQ_VELPARAMS ch1 to 0x50
out, want, got = req * n, 20 * n, bytearray()
t0 = time.monotonic()
while len(got) < want:
    if time.monotonic() - t0 > n / 100 + 30:
        sys.exit(f"lost bytes: {len(got)} of {want} after {time.monotonic() - t0:.1f} s")
    r, w, _ = select.select([fd], [fd] if out else [], [], 1.0)
    if w:
        try:
            out = out[os.write(fd, out):]
        except BlockingIOError:
            pass
    if r:
        got += os.read(fd, 65536)
secs = time.monotonic() - t0
frames = [got[i:i + 20] for i in range(0, len(got), 20)]
assert all(f[:2] == bytes([0x15, 0x04]) for f in frames), "not whole MOT_GET_VELPARAMS frames"
print(f"sim-speed: {n} pairs, {len(got)} reply bytes, none lost, in {secs:.2f} s: "
      f"{n / secs:.0f} pairs/s ({len(got) / secs:.0f} B/s of the line's 11520)")
os.close(fd)
PY
kill -INT $tap; wait $tap || true
grep -q "matches what was forwarded" "$dir/tap.log" && echo "sim-speed: the tap's check: matches what was forwarded"
cpu=$(ps -o times= -p $sim)
echo "sim-speed: the simulator's CPU time: ${cpu} s"
