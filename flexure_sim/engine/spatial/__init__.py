"""
The spatial engine: rigid bodies in space joined by flexure hinges with 6x6 stiffness.

The same method as the planar engine (the twistor-based potential energy method), with
bodies of six coordinates (position and a rotation vector relative to the rest orientation,
``rotation``), hinge deflections as unit dual quaternions or twists (``coordinates``), and a
6x6 stiffness per hinge (``stiffness``). A planar mechanism opened here gets its
out-of-plane degrees of freedom; its in-plane motion is the planar engine's.
"""
