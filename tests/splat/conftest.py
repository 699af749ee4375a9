"""Makes the float64 oracle (splat_reference.py, beside this file) importable by the splat tests."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
