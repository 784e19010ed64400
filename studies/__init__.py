"""Research studies: one folder per question (README.md, run.py, result/)."""
