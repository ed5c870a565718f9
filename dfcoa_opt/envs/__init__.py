"""Learning environments over the batched simulator, and the observation that policies share.

- :mod:`dfcoa_opt.envs.observation`: one robot's observation as a flat vector
  (:class:`~dfcoa_opt.envs.observation.ObservationSpec`, ``flatten``), shared by
  the environments and the ``policy:PATH`` controllers.
"""
