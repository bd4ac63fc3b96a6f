"""Shared set-up of the Python tests: the package from the build tree and the CLI executable."""

import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
LENSES = ROOT / "lenses"

try:
    import lensopt  # noqa: F401  (PYTHONPATH from ctest)
except ImportError:
    sys.path.insert(0, str(ROOT / "build" / "python"))
    import lensopt  # noqa: F401

EXECUTABLE = os.environ.get("LENSOPT_EXECUTABLE", str(ROOT / "build" / "lensopt"))

try:
    import torch  # noqa: F401

    HAVE_TORCH = True
except ImportError:
    HAVE_TORCH = False

# The baselines and the Zemax lenses of the acceptance comparison.
BASELINES = [LENSES / "doublet.toml", LENSES / "cooke.toml", LENSES / "tessar.toml"]
ZMX = sorted((LENSES / "zmx").glob("*.zmx"))

# The slower torch and example tests (seconds each; the whole suite ~1.5 min at a load average
# of 13 on 2 cores) run by default; LENSOPT_PYTHON_FULL_TESTS=0 skips them.
FULL = os.environ.get("LENSOPT_PYTHON_FULL_TESTS", "1") != "0"
FULL_REASON = "LENSOPT_PYTHON_FULL_TESTS=0: the slower torch/example tests are skipped"
