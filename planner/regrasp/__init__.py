"""Regrasping through the table: stable placements of the object where one hand sets it down for the other."""
