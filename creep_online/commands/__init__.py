"""One module per ``creep-online`` sub-command, each exposing ``register(subparsers)``."""
