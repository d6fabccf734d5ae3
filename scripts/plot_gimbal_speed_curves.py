"""Plot speed vs speed byte for PTS-303H model units (same as ``foveatrack gimbal curves``).

    python scripts/plot_gimbal_speed_curves.py out/gimbal_curves.png [seed ...]
"""

import sys

from foveatrack.cli.gimbal_cmd import main

if __name__ == "__main__":
    out = sys.argv[1] if len(sys.argv) > 1 else "gimbal_speed_curves.png"
    seeds = sys.argv[2:] or ["0", "1"]
    sys.exit(main(["curves", "--plot", out, "--unit-seeds", *seeds]))
