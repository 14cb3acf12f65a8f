"""C3D interoperability of the Rust capture module with an independent implementation.

ezc3d (https://github.com/pyomeca/ezc3d, PyPI package ``ezc3d``, which pulls in
``numpy``) writes C3D files that the Rust reader must read exactly, and reads the file
the Rust writer produces. The Rust side is the example ``examples/c3d_dump.rs``, run
with ``cargo run --release --example c3d_dump`` from the repository root.

Run:  pip install pytest ezc3d  &&  python -m pytest tests/c3d_interop.py -v

Exactness: C3D float data are IEEE f32 in the file's unit. Both sides convert an f32
millimetre (centimetre) value to metres as ``float64(value) / 1000`` (``/ 100``), a
correctly rounded IEEE division, and the Rust JSON prints f64 in shortest round-trip
form, so coordinates are compared with ``==``.
"""

import json
import math
import pathlib
import subprocess

import pytest

np = pytest.importorskip("numpy")
ezc3d = pytest.importorskip("ezc3d")

REPO = pathlib.Path(__file__).resolve().parents[1]


def c3d_dump(*args):
    """Runs the Rust example and returns its JSON output."""
    proc = subprocess.run(
        ["cargo", "run", "--release", "--quiet", "--example", "c3d_dump", "--", *args],
        cwd=REPO,
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, f"c3d_dump failed:\n{proc.stderr}"
    return json.loads(proc.stdout)


def known_points(n_markers, n_frames):
    """Coordinates in the file unit with non-trivial fractions, as float32 values."""
    m = np.arange(n_markers)[None, :, None]
    f = np.arange(n_frames)[None, None, :]
    axis = np.arange(3)[:, None, None]
    xyz = 123.456 * (axis + 1) - 37.25 * m + 1.0 / 3.0 * f * (m + 1) + 0.001 * axis * f
    xyz = xyz.astype(np.float32)
    pts = np.ones((4, n_markers, n_frames))
    pts[:3] = xyz
    return pts


def write_with_ezc3d(path, labels, rate, pts, residuals, units=None, analog=None):
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = np.array([rate])
    c3d["parameters"]["POINT"]["LABELS"]["value"] = tuple(labels)
    if units is not None:
        c3d["parameters"]["POINT"]["UNITS"]["value"] = [units]
    if analog is not None:
        channels, samples_per_frame = analog
        n_frames = pts.shape[2]
        c3d["parameters"]["ANALOG"]["RATE"]["value"] = np.array([rate * samples_per_frame])
        c3d["parameters"]["ANALOG"]["LABELS"]["value"] = tuple(
            f"A{k}" for k in range(channels)
        )
        c3d["data"]["analogs"] = (
            np.arange(channels * n_frames * samples_per_frame, dtype=float)
            .reshape(1, channels, n_frames * samples_per_frame)
            * 0.5
        )
    c3d["data"]["points"] = pts
    c3d["data"]["meta_points"]["residuals"] = residuals
    c3d.write(str(path))


def check_rust_reads(path, labels, rate, pts, missing, divisor, units):
    got = c3d_dump(str(path))
    n_markers, n_frames = pts.shape[1], pts.shape[2]
    assert got["labels"] == labels
    assert got["rate_hz"] == rate
    assert got["units"] == units
    assert got["first_frame"] == 1
    assert len(got["frames"]) == n_frames
    for f in range(n_frames):
        assert len(got["frames"][f]) == n_markers
        for m in range(n_markers):
            p = got["frames"][f][m]
            if (m, f) in missing:
                assert p is None, f"frame {f} marker {m} should be missing"
            else:
                expected = [float(np.float32(pts[a, m, f])) / divisor for a in range(3)]
                assert p == expected, f"frame {f} marker {m}: {p} != {expected}"


def test_rust_reads_ezc3d_file_mm(tmp_path):
    labels = ["LFT1", "RGT1", "marker three", "M4", "M5"]
    n_frames = 9
    pts = known_points(len(labels), n_frames)
    residuals = np.zeros((1, len(labels), n_frames))
    missing = {(1, 0), (1, 1), (4, 5), (0, 8), (2, 3)}
    for m, f in missing:
        residuals[0, m, f] = -1.0
    path = tmp_path / "ezc3d_mm.c3d"
    write_with_ezc3d(path, labels, 120.0, pts, residuals, analog=(3, 4))
    # ezc3d itself sees what we wrote.
    back = ezc3d.c3d(str(path))
    assert back["data"]["analogs"].shape == (1, 3, n_frames * 4)
    check_rust_reads(path, labels, 120.0, pts, missing, 1000.0, "mm")


def test_rust_reads_ezc3d_file_cm(tmp_path):
    labels = ["a", "bb", "ccc"]
    n_frames = 5
    pts = known_points(len(labels), n_frames)
    residuals = np.zeros((1, len(labels), n_frames))
    missing = {(2, 4), (0, 0)}
    for m, f in missing:
        residuals[0, m, f] = -1.0
    path = tmp_path / "ezc3d_cm.c3d"
    write_with_ezc3d(path, labels, 100.0, pts, residuals, units="cm")
    check_rust_reads(path, labels, 100.0, pts, missing, 100.0, "cm")


def synthetic_expected():
    """The fixed capture written by `c3d_dump --write` (metres, None = missing)."""
    frames = []
    for f in range(6):
        row = []
        for m in range(4):
            if (f * 4 + m) % 7 == 2:
                row.append(None)
            else:
                row.append(
                    [
                        0.1234567 * m - 0.25 + 0.003 * f,
                        -0.5 + 0.05 * m * m + 0.0101 * f,
                        1.75 - 0.00681 * f * f + 0.001 * m,
                    ]
                )
        frames.append(row)
    return ["LFT1", "RGT1", "marker three", "M4"], 120.0, 3, frames


def test_ezc3d_reads_rust_file(tmp_path):
    path = tmp_path / "rust.c3d"
    rust = c3d_dump("--write", str(path))
    labels, rate, first_frame, expected = synthetic_expected()

    c3d = ezc3d.c3d(str(path))
    assert list(c3d["parameters"]["POINT"]["LABELS"]["value"]) == labels
    assert c3d["parameters"]["POINT"]["UNITS"]["value"] == ["mm"]
    assert c3d["parameters"]["POINT"]["RATE"]["value"][0] == rate
    assert c3d["header"]["points"]["frame_rate"] == rate
    # ezc3d reports frames 0-based.
    assert c3d["header"]["points"]["first_frame"] + 1 == first_frame
    pts = c3d["data"]["points"]
    residuals = c3d["data"]["meta_points"]["residuals"]
    assert pts.shape == (4, len(labels), len(expected))

    assert rust["labels"] == labels
    assert rust["first_frame"] == first_frame
    for f, row in enumerate(expected):
        for m, p in enumerate(row):
            if p is None:
                assert residuals[0, m, f] == -1.0
                assert all(math.isnan(pts[a, m, f]) for a in range(3))
                assert rust["frames"][f][m] is None
                continue
            assert residuals[0, m, f] >= 0.0
            mm = [float(pts[a, m, f]) for a in range(3)]
            # ezc3d's values are the f32 millimetres of the intended metres ...
            assert mm == [float(np.float32(c * 1000.0)) for c in p]
            # ... and exactly what the Rust reader returns for the same file.
            assert rust["frames"][f][m] == [v / 1000.0 for v in mm]
