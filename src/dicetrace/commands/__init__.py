"""Sub-commands of the ``dicetrace`` CLI (one module each, ``register(app)``)."""
