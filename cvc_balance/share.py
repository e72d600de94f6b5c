"""
Where the package's bundled files (config/, bags/) are.

Installed by colcon: ``share/cvc_balance/`` found through the ament index.
From a source checkout (pip's editable install, the tests): the repository.
"""

from pathlib import Path

PACKAGE = 'cvc_balance'


def bundled_path(relative):
    """Return the path of a bundled file, such as config/ct_gantry.yaml."""
    try:
        from ament_index_python.packages import get_package_share_directory
        installed = Path(get_package_share_directory(PACKAGE)) / relative
        if installed.exists():
            return installed
    except (ImportError, LookupError, OSError, ValueError):
        pass  # not installed through ament: use the source tree
    return Path(__file__).resolve().parents[1] / relative
