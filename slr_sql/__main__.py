"""``python -m slr_sql`` is the ``slr`` command."""
from .cli import main

if __name__ == "__main__":
    main(prog_name="slr")
