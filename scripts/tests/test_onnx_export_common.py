"""The exporters' shared helpers that need no torch/onnx: run with `.venv/bin/python -m pytest scripts/tests`."""

import hashlib
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import onnx_export_common as common  # noqa: E402


def test_paths_point_into_the_repository():
    assert (common.REPO_ROOT / "Cargo.toml").is_file()
    assert (common.ASSETS / "clip_tokenizer.json").is_file()
    assert (common.ASSETS / "t5_tokenizer.json").is_file()


def test_sha256_matches_hashlib(tmp_path):
    f = tmp_path / "blob"
    data = bytes(range(256)) * 5000  # > one 1 MiB read block
    f.write_bytes(data)
    assert common.sha256(f) == hashlib.sha256(data).hexdigest()


def test_check_close_accepts_within_and_rejects_beyond_tolerance(capsys):
    ref = np.array([1.0, -2.0, 4.0], dtype=np.float32)
    # tolerance = 1e-4 + 1e-4 * 4 = 5e-4
    common.check_close(ref + 4e-4, ref, 1e-4, 1e-4, "ok")
    assert "[verify] ok" in capsys.readouterr().out
    with pytest.raises(SystemExit, match="beyond tolerance"):
        common.check_close(ref + 6e-4, ref, 1e-4, 1e-4, "too far")
    with pytest.raises(SystemExit):
        common.check_close(np.array([1.0, np.nan, 4.0]), ref, 1.0, 1.0, "nan")


def test_versions_lists_each_module_and_python():
    v = common.versions({"numpy": "numpy"})
    assert v == {"numpy": np.__version__, "python": sys.version.split()[0]}
