"""Paper steps 2-3, interpolate and model: the model interface, its registry and one module per kind."""
