"""Make clips for tools/checks/voice_truth.py from videos of people speaking: each video's sound, and its
speaker's lips measured in every frame (MediaPipe Face Mesh, in the photo environment).

    python tools/checks/voice_lips.py VIDEO [VIDEO ...] -o DATA_FOLDER

writes ``NAME.wav`` and ``NAME_lips.csv`` per video (``puppet.bench.voicetruth.clip_from_video``).
"""

from __future__ import annotations

import argparse

from puppet.bench.voicetruth import clip_from_video, read_lips


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("videos", nargs="+", help="videos with sound of a person speaking to the camera")
    parser.add_argument("-o", "--out", required=True, help="the folder for the clips")
    args = parser.parse_args()
    for video in args.videos:
        wav = clip_from_video(video, args.out)
        times, opening = read_lips(wav.with_name(f"{wav.stem}_lips.csv"))
        print(f"{wav}: {len(times)} frames with a face, lips open {opening.max():.3f} face widths at most")


if __name__ == "__main__":
    main()
