"""Package data: camera profiles (``cameras/``) and target patterns (``patterns/``) as TOML."""

from pathlib import Path

ASSETS_DIR = Path(__file__).resolve().parent
