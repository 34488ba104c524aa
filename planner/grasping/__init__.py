"""Single-grasp lists (paper IV-A): the object's point set, finger workspaces, grasp search and quality."""
