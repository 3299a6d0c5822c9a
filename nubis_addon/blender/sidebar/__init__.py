"""The interface in the 3D viewport's sidebar (tab Nubis): the property groups (properties), the panels,
the buttons (operators; the Cloud Layers list's in skylayers, the Superstorms panel's in stormbuttons)
and the Paint Sky tool with its panel (paint).

May import: every folder of blender/ but headless/."""
