"""Exports of a run's tables to other tools' types (optional dependencies, imported on use)."""
