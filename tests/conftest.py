"""Shared test setup: the tests tree mirrors the packages (simsat/, restore/, reports/, cli/);
synthetic fixtures shared between test modules live in ``tests/support`` (importable as ``support``)."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
