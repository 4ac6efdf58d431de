"""lagjax: classical mechanics in JAX."""

__version__ = "0.1.0"
