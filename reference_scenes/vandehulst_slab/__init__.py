"""Canonical scene with a Mitsuba reference and an independent answer (independent.py): see card.md."""
