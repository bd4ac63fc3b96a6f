"""The examples in examples/ run (on tiny sizes)."""

import os
import subprocess
import sys
import tempfile
import unittest
from pathlib import Path

from support import FULL, FULL_REASON, HAVE_TORCH, LENSES, ROOT, lensopt

EXAMPLES = ROOT / "examples"


def run(script, *args):
    env = dict(os.environ)
    package_dir = str(Path(lensopt.__file__).resolve().parents[1])
    env["PYTHONPATH"] = package_dir + os.pathsep + env.get("PYTHONPATH", "")
    return subprocess.run([sys.executable, str(EXAMPLES / script), *map(str, args)], check=True,
                          capture_output=True, text=True, env=env).stdout


class Examples(unittest.TestCase):
    @unittest.skipUnless(FULL, FULL_REASON)
    def test_analyze_lens(self):
        with tempfile.TemporaryDirectory() as tmp:
            svg = Path(tmp) / "cooke.svg"
            out = run("analyze_lens.py", LENSES / "cooke.toml", "-o", svg, "--rings", "4",
                      "--fields", "3")
            self.assertIn("effective focal length", out)
            self.assertIn("<polyline", svg.read_text())

    @unittest.skipUnless(HAVE_TORCH, "python3-torch is not installed: the torch example is skipped")
    @unittest.skipUnless(FULL, FULL_REASON)
    def test_joint_doublet(self):
        out = run("joint_doublet.py", "--steps", "2", "--batch", "1", "--scene-width", "160",
                  "--scene-height", "96", "--crop", "32", "--held-out", "1", "--rings", "3",
                  "--threads", "2")
        for setting in ("fixed/fixed", "fixed/trained", "joint"):
            self.assertIn(f"| {setting} |", out)


if __name__ == "__main__":
    unittest.main()
