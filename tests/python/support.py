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

# Tests not yet run to completion on the (overloaded) development machine: opt in with
# LENSOPT_PYTHON_FULL_TESTS=1 (see BENCHMARKS.md, "Python package and lensopt.torch").
FULL = os.environ.get("LENSOPT_PYTHON_FULL_TESTS") == "1"
FULL_REASON = "set LENSOPT_PYTHON_FULL_TESTS=1 to run the slow torch/example tests"
