"""How well the mouth follows real speakers: correlation and lag, offline and live, against the
loudness baseline, measured in one run (``puppet.bench.voicetruth``).

    python tools/checks/voice_truth.py DATA_FOLDER [--json]

DATA_FOLDER holds clips as ``NAME.wav`` and ``NAME_lips.csv`` (per video frame: ``t_s``, the
inner-lip ``opening`` and ``face_width`` in pixels and ``found``), as ``tools/checks/voice_lips.py``
makes them from videos of people speaking. No such clips ship with the project: real recordings
carry their own licences, so they are kept outside it (the guide's "The voice" page says which
were used).
"""

from __future__ import annotations

import argparse
import json

from puppet.bench.voicetruth import clips, measure


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data", help="the folder of NAME.wav + NAME_lips.csv clips")
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = parser.parse_args()
    if not clips(args.data):
        parser.exit(2, f"voice_truth: {args.data}: no NAME.wav with a NAME_lips.csv beside it\n")
    result = measure(args.data)
    if args.json:
        print(json.dumps(result, indent=1))
        return
    print(f"{'clip':24} {'s':>6}  {'offline r / lag':>16}  {'live r / lag':>14}  {'loudness r / lag':>17}")
    rows = [*result["clips"].items(), ("pooled (Fisher z)", {"seconds": float("nan"), **result["pooled"]})]
    for name, row in rows:
        cells = [f"{row[m]['r']:.3f} / {row[m]['lag_ms']:+4.0f} ms" for m in ("offline", "live", "loudness")]
        print(f"{name:24} {row['seconds']:6.1f}  {cells[0]:>16}  {cells[1]:>14}  {cells[2]:>17}")


if __name__ == "__main__":
    main()
