"""Reports that regenerate the README's measured figures; ``python tools/NAME.py`` runs them and
the tests share their scenes."""
