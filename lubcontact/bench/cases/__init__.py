"""Stored problems with known answers: the reference cases and the hard-case suite (package data)."""
