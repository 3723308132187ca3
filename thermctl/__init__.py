"""thermctl: identify multi-zone building thermal network models and export them for MPC."""

__version__ = "0.1.0"

from .io import load_model, save_model  # noqa: E402
from .export import load_statespace  # noqa: E402

__all__ = ["load_model", "save_model", "load_statespace", "__version__"]
