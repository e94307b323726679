"""The Foxglove edge: each drone's 3D scene in Foxglove's own schemas, live and in recordings.

- :mod:`.scene`: pure: one drone's scene as plain data (base, body, catenary tether, tension
  arrow, uncertainty, motion capture, truth, mode colour);
- :mod:`.schemas`: that scene as ``foxglove.SceneUpdate`` and ``foxglove.FrameTransforms``;
- :mod:`.live`: Foxglove's WebSocket server fed from the bus (``serve --foxglove-port``);
- :mod:`.offline`: the scene channels of ``replay --offline``'s output file.

Nothing is imported here, so ``groundstation.foxglove.scene`` loads without foxglove-sdk.
"""
