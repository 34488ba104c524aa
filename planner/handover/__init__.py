"""Arms, reach and the handover (paper IV-B, V-C): grasp configurations, exchange position, double grasps."""
