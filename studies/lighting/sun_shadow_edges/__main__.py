from studies._shared.run_record import run_recorded

from .run import main

raise SystemExit(run_recorded(main, __package__))
