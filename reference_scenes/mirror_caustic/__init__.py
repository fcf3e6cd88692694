"""Canonical scene with an analytic reference: see card.md."""
