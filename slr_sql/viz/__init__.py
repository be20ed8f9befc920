"""Looking at a store from outside: a live Foxglove WebSocket view (``slr foxglove``,
``slr serve --foxglove``) and MCAP files (``slr export``), with the same channels:

* one channel per event type (complex event types included), topic ``/NAME/ARITY``, JSON
  messages ``{"arg1": .., .., "start": S, "end": E, "arrival": A}`` with a JSON schema
  from the type's arguments (:mod:`.channels`);
* the stored transforms as ``foxglove.FrameTransforms`` on ``/tf`` and ``/tf_static``;
* completeness marks on ``/slr/completeness``.

The parts import the ``foxglove-sdk`` / ``mcap`` packages when they run (the ``foxglove`` and
``mcap`` extras); this package itself needs neither.
"""
