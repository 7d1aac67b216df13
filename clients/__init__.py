"""Clients of a running motion-style service: the ``motion-style`` batch command line
(``cli``) and the Blender add-on (``blender/motion_style``, installed into Blender)."""
