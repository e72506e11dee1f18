"""Reports: HTML pages with PNG plots (needs the ``plots`` extra, matplotlib)."""
