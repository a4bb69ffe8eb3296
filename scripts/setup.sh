#!/usr/bin/env bash
# Installs everything mousepose needs on a Debian 12 machine, as root.
# Idempotent: when every package is already there it only checks and returns.
set -euo pipefail

packages=(
  # build
  build-essential pkg-config clang libclang-dev
  # depth cameras (OpenNI2 with its Dummy and PS1080 drivers)
  libopenni2-dev libopenni2-0
  # GenICam colour cameras (Aravis 0.8, its fake GigE Vision camera and tools)
  libaravis-dev aravis-tools libusb-1.0-0-dev
  # image processing, calibration and the paw cascade (OpenCV 4.6 and its shipped cascades)
  libopencv-dev opencv-data
  # video export and import
  ffmpeg
  # the live pose stream (ZeroMQ PUB, linked to Debian's libzmq through pkg-config)
  libzmq3-dev
  # sessions' compressed records (zstd, linked to Debian's libzstd through pkg-config: the
  # copy the crate would build of it is half a minute of every build from scratch)
  libzstd-dev
  # label files kept as HDF5 (DeepLabCut's .h5, SLEAP's .slp), linked through pkg-config
  libhdf5-dev
  # the soak through faults (scripts/soak): its own ext4 file system, filled at once, and
  # /metrics scraped
  e2fsprogs util-linux curl
  # whole-process wall time and peak memory (/usr/bin/time -v), builds compared back to back
  # (hyperfine): scripts/moseq2-check, scripts/replay-bench
  time hyperfine
  # batches on a Slurm cluster: scripts/slurm-test starts a one-node cluster on localhost
  slurm-wlm munge
  # the tests render the report and the daemon's live page in a headless browser
  chromium
  # the Python environment of `export nwb` (below)
  python3-venv
  # unit and rules checks (scripts/check-units)
  systemd udev
  # the Debian package (scripts/package: dpkg-shlibdeps, strip)
  dpkg-dev binutils
  # promtool: the tests check the alert rules of docs/metrics.md (promtool check rules)
  prometheus
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if ((${#missing[@]})); then
  if [[ $(id -u) -ne 0 ]]; then
    echo "setup: these packages are missing and installing them needs root: ${missing[*]}" >&2
    exit 1
  fi
  echo "setup: installing ${missing[*]}" >&2
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

# `mousepose export nwb` writes NWB with the ecosystem's own libraries, pynwb and ndx-pose,
# in a Python environment of mousepose's own (nwbinspector checks the files in the tests, and
# pyzmq runs the pose stream's documented subscriber; pylsl ships the liblsl that the LSL
# outlet loads, and reads it in the tests).
nwb_venv=/opt/mousepose/venv
if ! "$nwb_venv/bin/python3" -c 'import pynwb, ndx_pose, nwbinspector, zmq, pylsl, tables, sleap_io' >/dev/null 2>&1; then
  if [[ $(id -u) -ne 0 ]]; then
    echo "setup: the Python environment $nwb_venv (pynwb, ndx-pose) is missing and making it needs root" >&2
    exit 1
  fi
  # The same script the Debian package installs as /usr/share/mousepose/nwb-env.
  "$(dirname "$0")/nwb-env" "$nwb_venv"
fi

if ! command -v cargo >/dev/null 2>&1; then
  echo "setup: cargo is not on PATH; install the Rust toolchain (rustup) first" >&2
  exit 1
fi
