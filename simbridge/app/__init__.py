"""The application around the cores: settings declared once (pydantic), world and parameter files.

:mod:`simbridge.app.settings` declares every server setting once (its field, bounds,
description, environment variable and command-line option; the budget records come from it);
:mod:`simbridge.app.config` reads and validates the world and parameter files.
"""
