"""The package version, one place for the modules that write it into files
(pyproject.toml and CMakeLists.txt carry the same number)."""
__version__ = "0.1.0"
