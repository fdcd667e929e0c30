import os
import site
import subprocess
import sys
import sysconfig
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the CLI: small matrices, no BLAS threads
os.environ.setdefault("OMP_NUM_THREADS", "1")

import pytest  # noqa: E402

from railfmu.fmus.generate.build import build_all, default_out  # noqa: E402


@pytest.fixture(scope="session")
def fmu_dir():
    """Every FMU, built into the per-user cache as `railfmu build` does (the CLI tests use the same
    folder): rebuilt when any model definition, the generator or the runtime changed
    (railfmu.fmus.generate.build.definition_key), so a fresh clone builds everything once."""
    build_all(default_out())
    return default_out()


@pytest.fixture(scope="session")
def installed(tmp_path_factory):
    """A fresh venv holding only the railfmu wheel (built once per session, ``python -m build``,
    installed without dependencies, not editable): its python and what the install added to
    site-packages. The venv borrows this environment's dependencies through a ``.pth`` line (a
    path added that way is not a site directory, so this environment's editable railfmu stays
    out)."""
    root = Path(__file__).resolve().parents[1]
    tmp = tmp_path_factory.mktemp("install")
    res = subprocess.run([sys.executable, "-m", "build", "--wheel", "--outdir", str(tmp / "dist"), str(root)],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr[-2000:]
    wheel, = (tmp / "dist").glob("railfmu-*.whl")
    venv = tmp / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    python = venv / "bin" / "python"
    purelib = Path(subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                                  capture_output=True, text=True, check=True).stdout.strip())
    before = set(os.listdir(purelib))
    res = subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "--quiet",
                          "--no-deps", "--no-index", str(wheel)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr[-2000:]
    added = set(os.listdir(purelib)) - before
    (Path(purelib) / "_railfmu_test_deps.pth").write_text(
        "\n".join([sysconfig.get_paths()["purelib"], *site.getsitepackages()]) + "\n")
    return python, added
