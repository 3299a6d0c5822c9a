"""Nubis Clouds: the extension's entry point. It only registers; everything else lives in nubis_addon/."""

if __package__:  # as Blender loads an extension: bl_ext.<repository>.nubis
    from .nubis_addon import register, unregister
else:  # as a plain module: pytest imports a checkout's __init__.py so when the folder's name is no package name
    from nubis_addon import register, unregister

__all__ = ["register", "unregister"]
