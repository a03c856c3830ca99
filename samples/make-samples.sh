#!/usr/bin/env bash
# Regenerates the APT samples in this folder with `aptscope encode`, so every byte in them comes
# from the message table. Usage: samples/make-samples.sh [path/to/aptscope]
set -euo pipefail
cd "$(dirname "$0")"
A=${1:-../target/debug/aptscope}
e() { "$A" encode "$@"; }

# A KDC101 (K-Cube DC servo) session: identify, enable, home, status updates, an absolute move.
{
  e HW_REQ_INFO --dest usb
  e HW_GET_INFO serial_number=27000123 model_number=KDC101 hw_type=44 fw_major=3 fw_interim=0 fw_minor=11 hw_version=1 nchs=1
  e MOD_SET_CHANENABLESTATE chan_ident=CH1 enable_state=1
  e MOD_REQ_CHANENABLESTATE chan_ident=CH1
  e MOD_GET_CHANENABLESTATE chan_ident=CH1 enable_state=1
  e HW_START_UPDATEMSGS
  e MOT_MOVE_HOME chan_ident=CH1
  for p in 0 -1200 -5400 -9800; do
    e MOT_GET_DCSTATUSUPDATE chan_ident=CH1 position=$p velocity=120 status_bits='MOTOR_CONNECTED|HOMING|MOVING_CCW|ENABLED'
  done
  e MOT_MOVE_HOMED chan_ident=CH1
  e MOT_MOVE_ABSOLUTE chan_ident=CH1 absolute_position=171520
  for p in 20480 68608 121856 165376 171520; do
    e MOT_GET_DCSTATUSUPDATE chan_ident=CH1 position=$p velocity=300 status_bits='MOTOR_CONNECTED|HOMED|MOVING_CW|ENABLED'
  done
  e MOT_MOVE_COMPLETED chan_ident=CH1 position=171520 velocity=0 status_bits='MOTOR_CONNECTED|HOMED|SETTLED|ENABLED' --form 14
  e HW_STOP_UPDATEMSGS
} > kdc101-session.hex

# A BSC203 three-bay rack: the host asks the motherboard which bays are used, then talks to bays.
{
  for b in 0 1 2; do
    e RACK_REQ_BAYUSED bay_ident=$b --dest rack
    e RACK_GET_BAYUSED bay_ident=$b bay_state=1 --source rack
  done
  e MOD_IDENTIFY chan_ident=CH1 --dest rack
  for b in bay0 bay1 bay2; do
    e MOT_REQ_STATUSUPDATE chan_ident=CH1 --dest $b
    e MOT_MOVE_RELATIVE chan_ident=CH1 relative_distance=25600 --dest $b
  done
  e MOT_MOVE_COMPLETED chan_ident=CH1 --source bay1
  e MOT_MOVE_COMPLETED chan_ident=CH1 --source bay0
  e MOT_MOVE_STOP chan_ident=CH1 stop_mode=1 --dest bay2
  e MOT_MOVE_STOPPED chan_ident=CH1 --source bay2
} > bsc203-rack.hex

# The KDC101 session as a raw byte stream (what a serial line carries).
xxd -r -p kdc101-session.hex > kdc101-session.bin

# A damaged capture: garbage before, between and after frames, an unknown id, a length that
# matches no form, an absurd length, and a final frame cut short.
{
  echo "ff 00 55 aa"
  e HW_REQ_INFO
  echo "13 37 00"
  echo "ee ee 02 00 d0 01 12 34"            # unknown id 0xEEEE with a 2-byte packet
  e MOD_IDENTIFY chan_ident=CH1
  echo "53 04 04 00 a2 01 01 00 40 0d"      # MOT_MOVE_ABSOLUTE with 4 data bytes (no such form)
  echo "53 04 ff ff a2 01"                  # absurd length 0xFFFF
  e MOT_MOVE_ABSOLUTE chan_ident=CH1 absolute_position=200000 --dest bay1
  echo "91 04 0e 00 81 50 01 00 00 50"      # MOT_GET_DCSTATUSUPDATE cut off after 10 bytes
} > damaged.hex
xxd -r -p damaged.hex > damaged.bin

# An Elliptec bus (9600 baud, one line for all modules) as a raw capture of both directions:
# an ELL14 rotation mount at 0, an ELL9 slider at 1 and an ELL17 linear stage at 2. The host
# identifies them, moves each, readdresses the ELL17 to 5 and groups the slider with the mount;
# a button press on the mount sends BS/BO; a move out of range errors; one request is never
# answered. Host commands go without terminator, as many programs send them.
{
  printf '0in'; printf '0IN0E1140028420200117016800023000\r\n'
  printf '1in'; printf '1IN0911300123202315010013 00000020\r\n' | tr -d ' '
  printf '2in'; printf '2IN1111700456202217010 01C00000800\r\n' | tr -d ' '
  printf '0gs'; printf '0GS00\r\n'
  printf '0ho0'; printf '0GS09\r\n'; printf '0PO00000000\r\n'
  printf '0ma00008C00'; printf '0GS09\r\n'; printf '0PO00008C00\r\n'
  printf '1fw'; printf '1PO00000020\r\n'
  printf '2ma00002000'; printf '2PO00002000\r\n'
  printf '2mr00001000'; printf '2PO00003000\r\n'
  printf '2ca5'; printf '5GS00\r\n'
  printf '5gp'; printf '5PO00003000\r\n'
  printf '5ma0000F000'; printf '5GS0C\r\n'
  printf '0gv'; printf '0GV64\r\n'
  printf '0sv32'; printf '0GS00\r\n'
  printf '0BS09\r\n'; printf '0BO00004600\r\n'
  printf '1ga0'; printf '0GS00\r\n'
  printf '1gj'
} > elliptec-bus.txt

# The KDC101 session as captures with times and directions: pcapng, pcap, MCAP, a usbmon capture
# of the FTDI chip, and the logs of socat, jpnevulator, interceptty and xxd.
cd ..
cargo run -q -p aptscope-capture --example make_samples
python3 samples/make-textlogs.py
if command -v hexdump >/dev/null; then hexdump -C samples/kdc101-session.bin > samples/kdc101-session.hexdump.txt; fi

# Scripted host sessions against the simulators, recorded on a virtual clock (samples/sessions/).
cargo run -q -p aptscope-capture --example record_sessions -- samples/sessions
