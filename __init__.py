"""Nubis Clouds: the extension's entry point. It only registers; everything else lives in nubis_addon/."""

from .nubis_addon import register, unregister

__all__ = ["register", "unregister"]
