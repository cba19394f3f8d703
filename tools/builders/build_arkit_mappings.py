"""Write mappings/arkit_csv.yaml and mappings/arkit_osc.yaml: the ARKit routes, each blendshape
sent to the FAP vector that best reproduces it on the calibrated default face.

The vectors come from puppet/data/arkit_faps.json (tools/builders/build_default_rig.py solves them with
puppet.runtime.fapcalibration.fit_faps against the artist-made example of each blendshape); the
rows, comments and channel shaping are puppet.live.arkitroute's, which ``puppet calibrate-face``
also uses to write a face's own route.

    python tools/builders/build_arkit_mappings.py
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from puppet.live.arkitroute import write_routes

ROOT = Path(__file__).resolve().parents[2]
VECTORS = ROOT / "puppet" / "data" / "arkit_faps.json"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vectors", type=Path, default=VECTORS, help="the solved FAP vectors (JSON)")
    parser.add_argument("--out", type=Path, default=ROOT / "mappings", help="folder of the mappings")
    args = parser.parse_args(argv)
    document = json.loads(args.vectors.read_text())
    write_routes(document, args.out)
    print(f"{args.out}: arkit_csv.yaml and arkit_osc.yaml, {len(document['faps'])} blendshapes each")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
