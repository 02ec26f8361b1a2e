"""The public API's annotations type-check: mypy (the ``[tool.mypy]`` configuration of
pyproject.toml: the public modules, third-party packages without types ignored) reports no error,
and the package ships ``py.typed`` so that a user's type checker reads them."""

import os
import subprocess
import sys
import tomllib

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.long
def test_mypy_reports_no_error_on_the_public_modules():
    pytest.importorskip("mypy", reason="mypy is not installed (pip install -e '.[test]')")
    # the cache of pyproject's configuration (.mypy_cache): a first run reads numpy's stubs
    # (about a minute on 2 cores), a later one only what changed
    proc = subprocess.run([sys.executable, "-m", "mypy", "--no-color-output", "--no-error-summary"], cwd=ROOT,
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "error:" not in proc.stdout


def test_mypy_configuration_names_existing_public_modules():
    with open(os.path.join(ROOT, "pyproject.toml"), "rb") as f:
        project = tomllib.load(f)
    files = project["tool"]["mypy"]["files"]
    assert "omaps/__init__.py" in files and "omaps/errors.py" in files and "omaps/checks.py" in files
    missing = [p for p in files if not os.path.isfile(os.path.join(ROOT, p))]
    assert not missing
    assert "py.typed" in project["tool"]["setuptools"]["package-data"]["omaps"]
    assert any(r.startswith("mypy") for r in project["project"]["optional-dependencies"]["test"])


def test_the_package_is_marked_typed():
    import omaps

    assert os.path.isfile(os.path.join(os.path.dirname(omaps.__file__), "py.typed"))
