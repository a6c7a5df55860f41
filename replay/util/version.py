"""The version of the installed distribution, from its metadata (a leaf: imports nothing of replay).

Every module that records or prints the version imports it from here, never from the
package ``replay`` itself (an import contract in pyproject.toml forbids ``import replay``
inside the library).
"""

from importlib.metadata import PackageNotFoundError, version

DISTRIBUTION = "replay-nav"  # [project] name in pyproject.toml

try:
    __version__ = version(DISTRIBUTION)
except PackageNotFoundError:  # a source tree on sys.path without `pip install`
    __version__ = "0+unknown"
