"""A shipped mapping's brow control at the end of its travel bends the forehead no more than the
artist's own brow raise and frown do (issue 38: at full raise, arduino_sliders' brow FAPs and
frontalis together kinked the brows and creased the forehead, 137 degrees of bend where the
artist's raise bends 19)."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from devices.base import Sample
from puppet.bench.assets import shared_assets
from puppet.face.default import default_face, load_default_rig
from puppet.face.examples import load_examples
from puppet.io.shipped import shipped_mapping, shipped_mappings
from puppet.live.mappingfile import load_mapping
from puppet.runtime.creases import MARGIN, Hinges
from puppet.runtime.runtime import Runtime

ARKIT = shared_assets() / "makehuman" / "faceunits_arkit"
BROW_SLOTS = set(range(30, 36))  # raise_l/r_i/m/o_eyebrow, FAPs 31-36
ARTIST = {"high": ("browInnerUp", "browOuterUpLeft", "browOuterUpRight"), "low": ("browDownLeft", "browDownRight")}

pytestmark = pytest.mark.skipif(not ARKIT.is_dir(), reason="the artist's ARKit shapes are not in ../shared/assets")


@pytest.fixture(scope="module")
def forehead():
    """(runtime, the forehead's interior edges, a function giving the largest bend there in radians)."""
    face = default_face()
    runtime = Runtime(face, load_default_rig())
    hinges = Hinges.of(face.triangles)
    inside = np.zeros(len(face.vertices), dtype=bool)
    inside[next(r.vertices for r in runtime.rig.regions if r.name == "forehead")] = True
    edges = inside[hinges.edges].all(axis=1)

    def bend(posed: np.ndarray) -> float:
        return float(np.abs(hinges.bend(face.vertices, posed, face.triangles))[edges].max())

    return runtime, bend


@pytest.fixture(scope="module")
def artist(forehead):
    _, bend = forehead
    face = default_face()
    examples = load_examples(face, ARKIT)
    return {end: bend(face.vertices + sum(examples[name] for name in names)) for end, names in ARTIST.items()}


def brow_channels(name: str) -> dict[str, tuple[float, float]]:
    """The mapping's bipolar channels that raise and lower a brow (a slider or fader with a rest
    in the middle; the ARKit mappings' one-way shapes are the ARKit route's to check), with their
    (min, max) as the file gives them."""
    mapping = load_mapping(shipped_mapping(name))
    specs = yaml.safe_load(shipped_mapping(name).read_text("utf-8"))["channels"]
    return {ch: (float(specs[ch].get("min", -1.0)), float(specs[ch].get("max", 1.0)))
            for ch in mapping.channel_names
            if mapping.drives(ch)[0] & BROW_SLOTS and specs[ch].get("range") == "bipolar"}


BROW_MAPPINGS = [name for name in shipped_mappings() if brow_channels(name)]


def test_the_shipped_mappings_with_brows_are_checked():
    assert {"arduino_sliders", "midi_faders"} <= set(BROW_MAPPINGS)


@pytest.mark.parametrize("end", ["high", "low"])
@pytest.mark.parametrize("name", BROW_MAPPINGS)
def test_a_brow_control_at_the_end_of_its_travel_bends_the_forehead_no_more_than_the_artist(
        name, end, forehead, artist):
    runtime, bend = forehead
    mapping = load_mapping(shipped_mapping(name))
    mapping.idle = None
    for k in range(100):  # a second of readings at 100 Hz: the filters settle at the end
        for channel, (low, high) in brow_channels(name).items():
            device, key = channel.split(".", 1)
            mapping.feed(Sample(k * 10_000_000, device, {key: high if end == "high" else low}))
    posed, _ = runtime.deform_pose(mapping.pose(99 * 10_000_000))
    assert bend(posed) <= artist[end] + MARGIN, (
        f"{name}: the brows at their {end} end bend the forehead {np.degrees(bend(posed)):.0f} degrees, "
        f"the artist's {np.degrees(artist[end]):.0f}")
