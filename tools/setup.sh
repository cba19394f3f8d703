#!/usr/bin/env bash
# Set up facepuppet on a fresh machine: a virtualenv in .venv with the project and its test
# tools, and the system libraries headless rendering needs (Mesa EGL). Safe to run again.
# PYTHON and VENV pick another interpreter and folder, to test on each Python the project claims:
#   PYTHON=python3.13 VENV=.venv-py3.13 FACEPUPPET_NO_PHOTO=1 bash tools/test.sh
set -euo pipefail
cd "$(dirname "$0")/.."

PYTHON=${PYTHON:-python3}
VENV=${VENV:-.venv}
"$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 11))' || {
  echo "facepuppet needs Python >= 3.11; $PYTHON is $("$PYTHON" --version 2>&1)" >&2; exit 1; }

# Headless rendering uses moderngl's EGL context on Mesa (llvmpipe when there is no GPU).
need_egl() { ! { ldconfig -p | grep -q 'libEGL.so.1' && ldconfig -p | grep -q 'libEGL_mesa.so.0'; }; }
if need_egl; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo "setup: installing Mesa EGL (libegl1 libegl-mesa0 libgl1-mesa-dri) for headless rendering"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libegl1 libegl-mesa0 libgl1-mesa-dri >/dev/null
  else
    echo "setup: Mesa EGL is missing; install it (Debian/Ubuntu: sudo apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri)" >&2
    exit 1
  fi
fi

# Sound: PortAudio for microphones (audio://) and play-out (sounddevice loads it at run time), and
# espeak-ng, whose speech with known phonemes the voice tests listen to.
if ! { ldconfig -p | grep -q 'libportaudio.so.2' && command -v espeak-ng >/dev/null; }; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo "setup: installing PortAudio and espeak-ng (libportaudio2 espeak-ng) for the microphone and its tests"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libportaudio2 espeak-ng >/dev/null
  else
    echo "setup: PortAudio or espeak-ng is missing; install them (Debian/Ubuntu: sudo apt-get install libportaudio2 espeak-ng)" >&2
    exit 1
  fi
fi

# Xvfb lets the tests open the real live window (and take its screenshot) with no screen.
if ! command -v xvfb-run >/dev/null && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
  echo "setup: installing Xvfb (xvfb xauth) so the live window can be tested without a screen"
  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq xvfb xauth >/dev/null
fi

# Chromium: the program feed's page (`puppet live --serve`) is tested in a real browser, headless.
if ! command -v chromium >/dev/null && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
  echo "setup: installing Chromium so the program feed's page can be tested in a real browser"
  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null
fi

# python-rtmidi (the midi extra) has no wheel for the newest Pythons; building it needs ALSA's headers.
if "$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 13))' && ! pkg-config --exists alsa 2>/dev/null; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo "setup: installing libasound2-dev so python-rtmidi can be built for $("$PYTHON" --version 2>&1)"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libasound2-dev pkg-config >/dev/null
  else
    echo "setup: python-rtmidi must be built for this Python; install ALSA's headers (sudo apt-get install libasound2-dev)" >&2
    exit 1
  fi
fi

if [ ! -x "$VENV/bin/python" ]; then
  echo "setup: creating $VENV"
  "$PYTHON" -m venv "$VENV"
fi
"$VENV/bin/python" -m pip install -q --upgrade pip
# setuptools builds in ./build and keeps what is there: modules an older checkout had (before a
# move or a rename) would be installed beside the new ones, so every set-up builds afresh.
rm -rf build
"$VENV/bin/python" -m pip install -q --force-reinstall --no-deps . \
  && "$VENV/bin/python" -m pip install -q '.[test,midi,osc,docs,batch,ndi]'

# The photo environment: MediaPipe's face landmarks for `puppet face-from-photo` (its model ships
# in the wheel; it pins numpy < 2, so it lives apart from .venv). FACEPUPPET_NO_PHOTO=1 skips it.
if [ "${FACEPUPPET_NO_PHOTO:-0}" != 1 ]; then
  if [ ! -x .venv-photo/bin/python ]; then
    echo "setup: creating .venv-photo (MediaPipe face landmarks for face-from-photo)"
    "$PYTHON" -m venv .venv-photo
  fi
  .venv-photo/bin/python -m pip install -q 'mediapipe==0.10.21'
fi
echo "setup: ready ($VENV/bin/puppet)"
