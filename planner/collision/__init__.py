"""Collision checking, the only home of coal: robot and environment pairs, checkers, the object in the model, segments."""
