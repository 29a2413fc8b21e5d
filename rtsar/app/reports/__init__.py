"""Reports that regenerate the measured figures of docs/pages/; ``python tools/NAME.py`` runs
them and the tests share their scenes."""
