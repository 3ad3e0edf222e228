"""Data files shipped with trade-gym: generated textures, vehicle palette, model files and cards.

Imported as `trade_gym.assets` (the repo's assets/ folder, mapped in pyproject.toml). `ASSETS_DIR` locates the files
in an editable install and in a wheel; `trade`, which never imports `trade_gym`, finds the same folder with
`trade.model_file.shipped_assets_dir`.
"""

from pathlib import Path

ASSETS_DIR = Path(__file__).resolve().parent
