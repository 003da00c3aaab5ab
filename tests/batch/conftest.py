"""The batch tests' fixtures; their toy rig is batch_toy.py (importable by name, also in subprocesses)."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

from batch_toy import make_toy_workflow  # noqa: E402


@pytest.fixture
def toy():
    return make_toy_workflow()
