"""The .fap reader and writer: real corpus files, every format variant, round trips, bad files,
a writer killed mid-take, and streaming in bounded memory."""

import os
import re
import signal
import subprocess
import sys
import tracemalloc
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import puppet
from puppet.fap.table import clamp_ranges
from puppet.io.fapfile import (
    COUNT_WIDTH,
    DEFAULT_FPS,
    FapError,
    FapStream,
    FapWarning,
    FapWriter,
    iter_fap,
    read_fap,
    write_fap,
)

REPO = Path(__file__).resolve().parents[1]
CORPUS = Path(__file__).resolve().parents[2] / "shared" / "fap-corpus"

# Facts verified by reading each file: (fps or None without header, frames, first frame number,
# FAPs masked somewhere in the file).
CORPUS_FACTS = {
    "xface_test.fap": (25, 43, 0, "3-20,23-26,31-42,48-60,63"),
    "xface_joy_crlf.fap": (25, 108, 0, "3-26,39-42,48-60,63"),
    "vreng_jag.fap": (5, 169, 0, "3-68"),
    "vreng_eyes.fap": (2, 52, 1, "19-26"),
    "vreng_S100_anger.fap": (10, 23, 0, "31-38,51-60"),
    "greta_cpp_bari21_1.fap": (25, 408, 0, "3-13,16-17,19-26,31-38,41-63"),
    "greta_cpp_empty.fap": (25, 1, 0, ""),
    "semaine_example2_headerless.fap": (None, 50, 0, "3-68"),
    "greta_AU_Interpolation_1131.fap": (25, 1, 0, "19-22"),
    "greta_1-Welcome_1.fap": (25, 1, 0, "1"),
}
SIXTY_NINE = {"greta_AU_Interpolation_1131.fap", "greta_1-Welcome_1.fap"}


def fap_set(spec):
    out = set()
    for part in filter(None, spec.split(",")):
        a, _, b = part.partition("-")
        out.update(range(int(a), int(b or a) + 1))
    return out


def corpus_file(name):
    path = CORPUS / name
    if not path.is_file():
        pytest.skip(f"corpus file {path} not present")
    return path


def read_recording(path):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        stream = read_fap(path)
    return stream, [str(w.message) for w in caught if issubclass(w.category, FapWarning)]


def read_strict(path):
    with warnings.catch_warnings():
        warnings.simplefilter("error", FapWarning)
        return read_fap(path)


def content_lines(text):
    return [line.split() for line in text.splitlines() if line.strip()
            and not line.lstrip().startswith("#")]


def mask_line(faps, n=68):
    return " ".join("1" if i in faps else "0" for i in range(1, n + 1))


def write(tmp_path, text, name="t.fap", newline="\n"):
    path = tmp_path / name
    path.write_bytes(text.replace("\n", newline).encode())
    return path


# --- the corpus -----------------------------------------------------------------------------

@pytest.mark.parametrize("name", sorted(CORPUS_FACTS))
def test_corpus_file_parses_with_its_declared_facts(name):
    path = corpus_file(name)
    fps, frames, first, used = CORPUS_FACTS[name]
    stream, messages = read_recording(path)
    assert len(stream) == frames == stream.values.shape[0] == stream.mask.shape[0]
    assert stream.values.shape[1:] == stream.mask.shape[1:] == (68,)
    assert stream.viseme.shape == (frames, 4) and stream.expression.shape == (frames, 6)
    np.testing.assert_array_equal(stream.frame_numbers, first + np.arange(frames))
    assert set(np.flatnonzero(stream.mask.any(axis=0)) + 1) == fap_set(used)
    if fps is None:
        assert stream.fps == DEFAULT_FPS and stream.declared_frames is None
        assert any("no header" in m for m in messages)
    else:
        assert stream.fps == fps and stream.declared_frames == frames
        header = content_lines(path.read_text(errors="replace"))[0]
        assert stream.version == header[0] and stream.name == " ".join(header[1:-2])
    assert not any("declares" in m for m in messages)


@pytest.mark.parametrize("name", sorted(set(CORPUS_FACTS) - SIXTY_NINE))
def test_corpus_masks_and_values_match_the_raw_text(name):
    """An independent naive parse: after the header, lines alternate mask / values."""
    path = corpus_file(name)
    lines = content_lines(path.read_text(errors="replace"))
    if len(lines[0]) < 68:
        lines = lines[1:]
    masks = np.array([[t == "1" for t in m] for m in lines[0::2]])
    stream, messages = read_recording(path)
    np.testing.assert_array_equal(stream.mask, masks)
    for i, tokens in enumerate(lines[1::2]):
        raw = np.array(tokens[1:], dtype=float)
        assert stream.frame_numbers[i] == int(tokens[0])
        np.testing.assert_array_equal(stream.values[i][masks[i]], raw)  # exactly, never clamped
        assert not stream.values[i][~masks[i]].any()
    assert not any("clamp" in m for m in messages)


def test_corpus_values_beyond_the_editor_ranges_read_as_written():
    """1,408 values in 4 corpus files lie beyond the Greta editor's sliders; none is changed."""
    low, high = clamp_ranges()
    beyond = {}
    for name in CORPUS_FACTS:
        stream = read_recording(corpus_file(name))[0]
        out = stream.mask[:, 2:] & ((stream.values[:, 2:] < low[2:]) | (stream.values[:, 2:] > high[2:]))
        beyond[name] = int(out.sum())
    assert sum(beyond.values()) == 1408 and sum(n > 0 for n in beyond.values()) == 4
    jag = read_recording(corpus_file("vreng_jag.fap"))[0]
    assert jag.values[:, 48].max() == 56298 and jag.values[:, 13].min() == -1242


def test_corpus_java_greta_69_flag_masks_drop_the_trailing_slot():
    stream = read_fap(corpus_file("greta_AU_Interpolation_1131.fap"))
    assert stream.name == "AU Interpolation_1131.fap"
    np.testing.assert_array_equal(np.flatnonzero(stream.mask[0]) + 1, [19, 20, 21, 22])
    np.testing.assert_array_equal(stream.values[0, 18:22], [626, 626, 133, 133])
    welcome = read_fap(corpus_file("greta_1-Welcome_1.fap"))
    np.testing.assert_array_equal(np.flatnonzero(welcome.mask[0]) + 1, [1])
    np.testing.assert_array_equal(welcome.viseme[0], [0, 0, 63, 0])  # one token: select1


def test_corpus_values_keep_their_standard_meaning():
    """VREng divides version-2.0 values by 20; the reader does not."""
    stream = read_fap(corpus_file("vreng_eyes.fap"))
    assert stream.version == "2.0"
    np.testing.assert_array_equal(stream.values[-1, 18:26],
                                  [-500, -500, 100, 100, 0, 0, -100, -100])


# --- variants, in small synthetic files --------------------------------------------------------

def test_crlf_tabs_comments_and_blank_lines(tmp_path):
    text = ("# made by hand\n\n2.1 take 25 2\n# between header and mask\n\n"
            + mask_line({3, 4}).replace(" ", "\t") + "\t\n0\t100\t-20\n# between frames\n\n"
            + mask_line({3, 4}) + "\n1 110 -30\n#\n")
    path = write(tmp_path, text, newline="\r\n")
    stream = read_strict(path)
    assert len(stream) == 2 and stream.fps == 25 and stream.name == "take"
    np.testing.assert_array_equal(stream.values[:, 2:4], [[100, -20], [110, -30]])


def test_old_mac_line_endings(tmp_path):
    path = write(tmp_path, "2.1 take 25 1\n" + mask_line({3}) + "\n0 5\n", newline="\r")
    assert read_strict(path).values[0, 2] == 5


@pytest.mark.parametrize("version", ["2.0", "2.1", "2.2"])
def test_versions_and_names_with_spaces(tmp_path, version):
    path = write(tmp_path, f"{version} my long take name 30 1\n" + mask_line({19}) + "\n0 400\n")
    stream = read_strict(path)
    assert stream.version == version and stream.name == "my long take name"
    assert stream.fps == 30 and stream.declared_frames == 1
    assert stream.values[0, 18] == 400  # never divided by 20


def test_frames_numbered_from_one_are_kept_as_written(tmp_path):
    body = "".join(mask_line({3}) + f"\n{i} {i * 10}\n" for i in (1, 2, 3))
    stream = read_strict(write(tmp_path, "2.1 take 25 3\n" + body))
    np.testing.assert_array_equal(stream.frame_numbers, [1, 2, 3])
    np.testing.assert_array_equal(stream.values[:, 2], [10, 20, 30])


def test_no_header_assumes_25_fps_and_warns(tmp_path):
    path = write(tmp_path, "# payload\n" + mask_line({5}) + "\n0 7\n" + mask_line({5}) + "\n1 8\n")
    with pytest.warns(FapWarning, match=r"no header.*25 fps"):
        stream = read_fap(path)
    assert stream.fps == 25 and stream.declared_frames is None and len(stream) == 2
    assert stream.version == "" and stream.name == ""


def test_69_flag_masks(tmp_path):
    java = mask_line({3, 68}) + " 0"                  # FAPs 1..68, then Java Greta's unused slot
    leading = "0 " + mask_line({3, 68})               # an unused slot 0 first, recognised by FAP 68
    both = "1 " + mask_line({3, 68})
    for flags in (java, leading):
        stream = read_strict(write(tmp_path, f"2.1 take 25 1\n{flags}\n0 40 -50\n"))
        np.testing.assert_array_equal(np.flatnonzero(stream.mask[0]) + 1, [3, 68])
        np.testing.assert_array_equal(stream.values[0, [2, 67]], [40, -50])
    path = write(tmp_path, f"2.1 take 25 1\n{both}\n0 40 -50\n")
    with pytest.raises(FapError, match=rf"^{re.escape(str(path))}:2: expected a 69-flag mask"):
        read_fap(path)


@pytest.mark.parametrize("faps, tokens, viseme, expression", [
    ({1}, "4", [4, 0, 63, 0], [0] * 6),
    ({2}, "3", [0] * 4, [3, 63, 0, 0, 0, 0]),
    ({1, 2}, "4 3", [4, 0, 63, 0], [3, 63, 0, 0, 0, 0]),
    ({1}, "4 9 20 1", [4, 9, 20, 1], [0] * 6),
    ({2}, "3 40 5 10 1 0", [0] * 4, [3, 40, 5, 10, 1, 0]),
    ({1, 2}, "4 9 20 1 3 40 5 10 1 0", [4, 9, 20, 1], [3, 40, 5, 10, 1, 0]),
])
def test_fap_1_and_2_as_one_token_or_full_fields(tmp_path, faps, tokens, viseme, expression):
    path = write(tmp_path, "2.1 take 25 1\n" + mask_line(faps | {3, 4})
                 + f"\n0 {tokens} 111 -222\n")
    stream = read_strict(path)
    np.testing.assert_array_equal(stream.viseme[0], viseme)
    np.testing.assert_array_equal(stream.expression[0], expression)
    np.testing.assert_array_equal(stream.values[0, :4], [viseme[0], expression[0], 111, -222])


def test_mixed_fap_1_2_token_counts_are_an_error(tmp_path):
    path = write(tmp_path, "2.1 take 25 1\n" + mask_line({1, 2, 3}) + "\n0 4 9 20 1 3 7\n")
    with pytest.raises(FapError, match=rf"^{re.escape(str(path))}:3: expected 3 or 11 values"):
        read_fap(path)


def test_value_line_with_only_the_frame_number(tmp_path):
    empty = write(tmp_path, "2.1 empty 25 1\n" + mask_line(set()) + "\n0 \n", "empty.fap")
    stream = read_strict(empty)
    assert len(stream) == 1 and not stream.mask.any()
    masked = write(tmp_path, "2.1 take 25 2\n" + mask_line({3}) + "\n0 12\n"
                   + mask_line({3, 4}) + "\n1\n", "masked.fap")
    with pytest.warns(FapWarning, match=r"only the frame number.*line 5"):
        stream = read_fap(masked)
    np.testing.assert_array_equal(stream.mask.sum(axis=1), [1, 0])
    assert stream.values[0, 2] == 12 and not stream.values[1].any()


TWO_FRAMES = mask_line({3}) + "\n0 1\n" + mask_line({3}) + "\n1 2\n"


def test_header_count_larger_than_frames_present_warns_and_keeps_them(tmp_path):
    path = write(tmp_path, "2.1 take 25 9\n" + TWO_FRAMES)
    with pytest.warns(FapWarning, match=r"declares 9 frames.*holds 2"):
        stream = read_fap(path)
    assert len(stream) == 2 and stream.declared_frames == 9


def test_header_count_smaller_than_frames_present_warns_and_keeps_all(tmp_path):
    path = write(tmp_path, "2.1 take 25 1\n" + TWO_FRAMES)
    with pytest.warns(FapWarning, match=r"declares 1 frames.*holds 2"):
        assert len(read_fap(path)) == 2


def test_float_values_are_accepted(tmp_path):
    stream = read_strict(write(tmp_path, "2.1 take 25 1\n" + mask_line({3, 4}) + "\n0 12.5 -3e1\n"))
    np.testing.assert_array_equal(stream.values[0, 2:4], [12.5, -30])


def test_values_beyond_every_range_read_and_write_back_unchanged(tmp_path):
    """No clamping, no warning: the reader returns what the file says, the writer writes it back."""
    low, high = clamp_ranges()
    body = "".join(mask_line({3, 19, 1}) + f"\n{i} 20 0 99 0 {high[2] + 5} {low[18] - i - 1}\n"
                   for i in range(3))
    body += mask_line({49, 50}) + "\n3 56298 -100000000000000000000\n"
    path = write(tmp_path, "2.1 take 25 4\n" + body, "loud.fap")
    stream = read_strict(path)
    assert (stream.values[:3, 2] == high[2] + 5).all()
    np.testing.assert_array_equal(stream.values[:3, 18], low[18] - np.arange(1, 4))
    np.testing.assert_array_equal(stream.viseme[:3], [[20, 0, 99, 0]] * 3)
    assert stream.values[3, 48] == 56298 and stream.values[3, 49] == -1e20
    again = tmp_path / "again.fap"
    write_fap(again, stream)
    back = read_strict(again)
    for key in ("values", "mask", "viseme", "expression"):
        np.testing.assert_array_equal(getattr(back, key), getattr(stream, key))


# --- bad files: file:line: expected ..., found ... ---------------------------------------------

BAD_FILES = {
    "empty file": ("", 1, "end of file"),
    "only comments": ("# a\n\n# b\n", 4, "end of file"),
    "non-numeric value": ("2.1 t 25 2\n" + mask_line({3, 4}) + "\n0 1 2\n# c\n"
                          + mask_line({3, 4}) + "\n1 3 abc\n", 6, "'abc'"),
    "not finite": ("2.1 t 25 1\n" + mask_line({3}) + "\n0 nan\n", 3, "'nan'"),
    "mask of 50 flags": ("2.1 t 25 1\n\n" + "0 " * 50 + "\n0\n", 3, "50 flags"),
    "mask with a 2": ("2.1 t 25 1\n" + mask_line({3}).replace("1", "2") + "\n0 1\n", 2, "'2'"),
    "too few values": ("2.1 t 25 1\n" + mask_line({3, 4, 5}) + "\n0 1 2\n", 3, "2 values"),
    "too many values": ("2.1 t 25 1\n" + mask_line({3}) + "\n0 1 2\n", 3, "2 values"),
    "bad frame number": ("2.1 t 25 1\n" + mask_line({3}) + "\nx 1\n", 3, "'x'"),
    "missing value line": ("2.1 t 25 1\n" + mask_line({3}) + "\n# c\n", 4, "end of file"),
    "bad fps": ("2.1 t fast 1\n" + mask_line({3}) + "\n0 1\n", 1, "'fast'"),
    "bad count": ("2.1 t 25 -3\n" + mask_line({3}) + "\n0 1\n", 1, "'-3'"),
    "not a header": ("hello world\n" + mask_line({3}) + "\n0 1\n", 1, "'hello world'"),
    "underscored number": ("2.1 t 25 1\n" + mask_line({3, 4}) + "\n0 1 1_000\n", 3, "'1_000'"),
    "non-ASCII digits": ("2.1 t 25 1\n" + mask_line({3}) + "\n0 \u0661\u0662\n", 3, "'\u0661\u0662'"),
    "infinity": ("2.1 t 25 1\n" + mask_line({3}) + "\n0 -inf\n", 3, "'-inf'"),
    "fps 1e-300": ("2.1 t 1e-300 1\n" + mask_line({3}) + "\n0 1\n", 1, "'1e-300'"),
    "fps 1e300": ("2.1 t 1e300 1\n" + mask_line({3}) + "\n0 1\n", 1, "'1e300'"),
    "underscored fps": ("2.1 t 2_5 1\n" + mask_line({3}) + "\n0 1\n", 1, "'2_5'"),
    "count 1e100": ("2.1 t 25 1e100\n" + mask_line({3}) + "\n0 1\n", 1, "'1e100'"),
    "count 10^100": ("2.1 t 25 1" + "0" * 100 + "\n" + mask_line({3}) + "\n0 1\n", 1, "'1000"),
    "underscored count": ("2.1 t 25 1_0\n" + mask_line({3}) + "\n0 1\n", 1, "'1_0'"),
    "frame number 10^20": ("2.1 t 25 1\n" + mask_line({3}) + "\n100000000000000000000 1\n", 3,
                           "'100000000000000000000'"),
    "FAP 1 field 1e20": ("2.1 t 25 1\n" + mask_line({1}) + "\n0 1e20 0 63 0\n", 3, "1e+20"),
    "FAP 2 field 2.5": ("2.1 t 25 1\n" + mask_line({2}) + "\n0 2.5\n", 3, "2.5"),
    "a line of 1000 fields": ("2.1 t 25 1\n" + mask_line({3}) + "\n0" + " 1" * 1000 + "\n", 3,
                              "or more"),
    "a field of 1000 digits": ("2.1 t 25 1\n" + mask_line({3}) + "\n0 " + "9" * 1000 + "\n", 3,
                               "'99999999999999999999'"),
}


@pytest.mark.parametrize("case", sorted(BAD_FILES))
def test_bad_files_name_the_file_and_line(tmp_path, case):
    text, line, found = BAD_FILES[case]
    path = write(tmp_path, text, "bad.fap")
    with pytest.raises(FapError) as info:
        read_fap(path)
    message = str(info.value)
    assert re.match(rf"^{re.escape(str(path))}:{line}: expected .+, found ", message), message
    assert found in message.rsplit("found", 1)[1]


@pytest.mark.parametrize("line", ["1 " * 25_000_000, "9" * 50_000_000, " " * 50_000_000 + "x"])
def test_a_50_mb_line_is_refused_in_bounded_memory(tmp_path, line):
    path = tmp_path / "long.fap"
    path.write_text("2.1 t 25 1\n" + mask_line({3}) + "\n" + line + "\n")
    tracemalloc.start()
    try:
        with pytest.raises(FapError, match=r"long.fap:3: expected"):
            read_fap(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 8_000_000


def test_a_50_mb_comment_line_is_skipped_in_bounded_memory(tmp_path):
    path = tmp_path / "comment.fap"
    path.write_text("2.1 t 25 1\n#" + "x " * 25_000_000 + "\n" + mask_line({3}) + "\n0 7\n")
    tracemalloc.start()
    try:
        stream = read_strict(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert stream.values[0, 2] == 7 and peak < 8_000_000


def test_fap_error_is_a_value_error():
    assert issubclass(puppet.FapError, ValueError)


# --- writing ------------------------------------------------------------------------------------

def random_stream(seed, n, fap1, fap2):
    rng = np.random.default_rng(seed)
    low, high = clamp_ranges()
    low, high = np.where(np.isinf(low), -5000, low), np.where(np.isinf(high), 5000, high)
    mask = rng.random((n, 68)) < rng.random()
    mask[:, 0] &= fap1
    mask[:, 1] &= fap2
    values = rng.integers(low.astype(int), high.astype(int) + 1, size=(n, 68)) * mask
    viseme = rng.integers(0, [15, 15, 64, 2], size=(n, 4)) * mask[:, :1]
    expression = rng.integers(0, [7, 64, 7, 64, 2, 2], size=(n, 6)) * mask[:, 1:2]
    values[:, 0], values[:, 1] = viseme[:, 0], expression[:, 0]
    return values.astype(float), mask, viseme, expression


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(0, 12), fps=st.integers(1, 120),
       name=st.text(st.characters(codec="utf-8"), max_size=12), fap1=st.booleans(),
       fap2=st.booleans(), streaming=st.booleans())
def test_written_streams_round_trip_exactly(tmp_path_factory, seed, n, fps, name, fap1, fap2,
                                           streaming):
    path = tmp_path_factory.mktemp("rt") / "take.fap"
    values, mask, viseme, expression = random_stream(seed, n, fap1, fap2)
    if streaming:
        with FapWriter(path, fps, name) as out:
            for i in range(n):
                out.write_frame(values[i], mask[i], viseme[i] if mask[i, 0] else None,
                                expression[i] if mask[i, 1] else None)
    else:
        write_fap(path, FapStream(fps, values, mask, viseme, expression, np.arange(n) + 5, name))
    stream = read_strict(path)
    assert stream.fps == fps and stream.version == "2.1" and stream.declared_frames == n
    assert stream.name == ("_".join(name.split()) or "take")
    np.testing.assert_array_equal(stream.values.reshape(n, 68), values)
    np.testing.assert_array_equal(stream.mask.reshape(n, 68), mask)
    np.testing.assert_array_equal(stream.viseme.reshape(n, 4), viseme)
    np.testing.assert_array_equal(stream.expression.reshape(n, 6), expression)
    np.testing.assert_array_equal(stream.frame_numbers, np.arange(n))


def test_written_file_is_in_the_portable_form(tmp_path):
    values, mask, viseme, expression = random_stream(7, 6, True, True)
    values[:, 2:] += 0.4 * mask[:, 2:]
    path = tmp_path / "p.fap"
    write_fap(path, FapStream(25.0, values, mask, viseme, expression, np.arange(6), "a b\tc"))
    raw = path.read_bytes()
    assert b"\r" not in raw
    lines = raw.decode().split("\n")
    assert re.fullmatch(r"2\.1 a_b_c 25 6 *", lines[0]) and lines[-1] == ""
    for i, (flags, vals) in enumerate(zip(lines[1:-1:2], lines[2:-1:2])):
        assert len(flags.split()) == 68 and set(flags.split()) <= {"0", "1"}
        assert all(re.fullmatch(r"-?\d+", t) for t in vals.split())
        assert vals.split()[0] == str(i)
        if mask[i, 0]:
            assert vals.split()[1:5] == [str(v) for v in viseme[i]]  # full fields, as Xface
    np.testing.assert_array_equal(read_strict(path).values, np.rint(values))


def test_write_fap_from_arrays(tmp_path):
    values = np.zeros((3, 68))
    values[:, 2] = [10, 0, 30]
    values[1, 40] = -7
    values[2, 0] = 5                                     # FAP 1 select, written as full fields
    write_fap(tmp_path / "v.fap", values, fps=50)
    stream = read_strict(tmp_path / "v.fap")
    assert stream.fps == 50 and stream.name == "take"
    np.testing.assert_array_equal(stream.values, values)
    np.testing.assert_array_equal(np.flatnonzero(stream.mask.all(axis=0)) + 1, [1, 3, 41])
    assert not stream.mask[:, ~np.isin(np.arange(68), [0, 2, 40])].any()
    np.testing.assert_array_equal(stream.viseme[2], [5, 0, 63, 0])
    mask = values != 0
    puppet.write_fap(tmp_path / "vm.fap", (values, mask))
    stream = read_strict(tmp_path / "vm.fap")
    np.testing.assert_array_equal(stream.mask, mask)
    assert stream.fps == DEFAULT_FPS


def test_non_integer_fps_is_rounded_with_a_warning(tmp_path):
    with pytest.warns(FapWarning, match="29.97 written as 30"):
        write_fap(tmp_path / "f.fap", np.zeros((1, 68)), fps=29.97)
    assert read_strict(tmp_path / "f.fap").fps == 30


def test_writer_default_mask_and_validation(tmp_path):
    with FapWriter(tmp_path / "w.fap", 25, "w") as out:
        out.write_frame(np.arange(68.0))
        out.write_frame(np.zeros(68), viseme=[3, 4, 5, 1])
        with pytest.raises(ValueError):
            out.write_frame(np.zeros(67))
        with pytest.raises(ValueError):
            out.write_frame(np.full(68, np.nan))
    stream = read_strict(tmp_path / "w.fap")
    assert stream.mask[:, 2:].all() and not stream.mask[0, :2].any()
    assert stream.mask[1, 0] and not stream.mask[1, 1]
    np.testing.assert_array_equal(stream.values[0, 2:], np.arange(2.0, 68))
    np.testing.assert_array_equal(stream.viseme[1], [3, 4, 5, 1])
    with pytest.raises(ValueError):
        out.write_frame(np.zeros(68))


def test_writer_file_is_valid_after_every_frame(tmp_path):
    path = tmp_path / "live.fap"
    with FapWriter(path, 25, "live") as out:
        assert len(read_strict(path)) == 0
        for i in range(4):
            out.write_frame(np.full(68, 10.0 * i))
            stream = read_strict(path)
            assert len(stream) == stream.declared_frames == i + 1
    header = path.read_text().split("\n")[0]
    assert header == "2.1 live 25 " + "4".ljust(COUNT_WIDTH)


KILLED_WRITER = """
import os, signal, sys
import numpy as np
from puppet.io.fapfile import FapWriter
out = FapWriter(sys.argv[1], 25, "killed")
for i in range(int(sys.argv[2])):
    out.write_frame((np.arange(68) % 7 + i) * 10.0)
os.kill(os.getpid(), signal.SIGKILL)
"""


def test_writer_killed_mid_take_leaves_every_completed_frame(tmp_path):
    path, k = tmp_path / "killed.fap", 7
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(REPO),
                                                                    os.environ.get("PYTHONPATH")])))
    done = subprocess.run([sys.executable, "-c", KILLED_WRITER, str(path), str(k)], env=env,
                          capture_output=True, timeout=60)
    assert done.returncode == -signal.SIGKILL, done.stderr.decode()
    stream = read_strict(path)                    # exact count in place: no warning
    assert len(stream) == stream.declared_frames == k
    expected = (np.arange(68) % 7 + np.arange(k)[:, None]) * 10.0
    np.testing.assert_array_equal(stream.values[:, 2:], expected[:, 2:])
    assert stream.mask[:, 2:].all() and not stream.mask[:, :2].any()


# --- streaming ----------------------------------------------------------------------------------

def test_iter_fap_gives_the_header_first_and_frames_lazily(tmp_path):
    body = "".join(mask_line({3}) + f"\n{i} {i}\n" for i in range(1000))
    path = write(tmp_path, "# c\n2.1 lazy 12 1001\n" + body + mask_line({3}) + "\n1000 oops\n")
    with iter_fap(path) as reader:
        assert reader.header.fps == 12 and reader.header.name == "lazy"
        assert reader.header.declared_frames == 1001
        first = next(reader)
        assert first.number == 0 and first.mask[2] and first.values.shape == (68,)
        with pytest.raises(FapError, match=r":2004: expected a number"):
            for _ in reader:
                pass


def test_streaming_a_long_take_in_bounded_memory(tmp_path):
    path, n = tmp_path / "long.fap", 12_000
    rng = np.random.default_rng(1)
    frames = rng.integers(0, 300, size=(50, 68)).astype(float)
    with FapWriter(path, 25, "long", flush=False) as out:
        for i in range(n):
            out.write_frame(frames[i % 50])
    assert path.stat().st_size > 4_000_000
    tracemalloc.start()
    try:
        count, total = 0, 0.0
        with warnings.catch_warnings():
            warnings.simplefilter("error", FapWarning)
            for frame in iter_fap(path):
                count += 1
                total += frame.values[2]
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert count == n and total == sum(frames[i % 50, 2] for i in range(n))
    assert peak < 1_000_000   # the values alone would take 12k x 68 x 8 = 6.5 MB


def test_a_take_cut_off_mid_frame_reads_to_its_last_complete_frame(tmp_path):
    """Every byte a killed FapWriter can stop at: the frames before it read back, with a warning."""
    path = tmp_path / "whole.fap"
    with FapWriter(path, 25, "cut") as writer:
        for i in range(3):
            writer.write_frame(np.full(68, float(i + 1)))
    data = path.read_bytes()
    head = data.index(b"\n") + 1
    ends = [i + 1 for i in range(len(data)) if data[i:i + 1] == b"\n"]
    for cut in range(head + 1, len(data)):
        complete = sum(1 for e in ends[2::2] if e <= cut)  # frame k ends at the (2k + 3)-th newline
        count = f"{complete}".ljust(COUNT_WIDTH).encode()
        cut_file = tmp_path / "cut.fap"
        cut_file.write_bytes(data[:head].replace(b"3".ljust(COUNT_WIDTH), count) + data[head:cut])
        with warnings.catch_warnings(record=True):
            warnings.simplefilter("always")
            stream = read_fap(cut_file)
        assert len(stream) == complete, cut
        np.testing.assert_array_equal(stream.values[:, 2], np.arange(1, complete + 1))


def test_a_cut_frame_the_header_counts_is_still_an_error(tmp_path):
    path = write(tmp_path, "2.1 t 25 2\n" + mask_line({3}) + "\n0 1\n" + mask_line({3}) + "\n1 5 6", "bad.fap")
    with pytest.raises(FapError, match=r"bad.fap:5: expected"):
        read_fap(path)
