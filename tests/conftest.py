import sys
from pathlib import Path

# tests/scan/twins.py and friends are imported as plain modules by the tests beside them.
sys.path.insert(0, str(Path(__file__).parent))
