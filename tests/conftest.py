import pytest

from fmus.build import build_all


@pytest.fixture(scope="session")
def fmu_dir(tmp_path_factory):
    """Every FMU, freshly built for this test session."""
    out = tmp_path_factory.mktemp("fmus")
    build_all(out, force=True)
    return out
