import sys
from pathlib import Path

# daemon_procs.py (helpers for the multi-process tests) is imported as a plain module.
sys.path.insert(0, str(Path(__file__).parent))
