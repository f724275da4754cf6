"""The bpy side of GI Preview: engine, scene export, properties, panels, operators."""
