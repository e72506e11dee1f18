"""``python -m creep_online`` runs the command line."""
from .cli import console

console()
