"""Data files shipped with trade-gym: generated textures, vehicle palette, model files and cards.

`ASSETS_DIR` locates them both in a source checkout and in a non-editable install.
"""

from pathlib import Path

ASSETS_DIR = Path(__file__).resolve().parent
