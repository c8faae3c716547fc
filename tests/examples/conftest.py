"""Running the examples as a user does: `python examples/NAME.py ...`, on small inputs."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def run_example(name: str, *args: object, timeout: float = 600) -> subprocess.CompletedProcess:
    """Run examples/NAME.py with arguments; fail with its output if it fails."""
    result = subprocess.run([sys.executable, str(EXAMPLES / f"{name}.py"), *map(str, args)],
                            capture_output=True, text=True, timeout=timeout)
    if result.returncode != 0:
        pytest.fail(f"{name}.py exited {result.returncode}\n{result.stdout}\n{result.stderr}")
    return result


@pytest.fixture(scope="session")
def examples_on_path():
    """Make the examples importable (their helpers and pure functions)."""
    sys.path.insert(0, str(EXAMPLES))
    yield
    sys.path.remove(str(EXAMPLES))
