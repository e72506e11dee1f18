"""Data in: files and live transports. Each source yields samples; nothing bad passes as good."""
from .csvfile import load_csv, save_csv

__all__ = ["load_csv", "save_csv"]
