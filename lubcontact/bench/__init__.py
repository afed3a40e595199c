"""Tooling around the core, never imported by it: problem sets, timed runs, reports, hard cases.

Commands: ``lubcontact bench``, ``lubcontact compare``, ``lubcontact check-hard``.
"""
