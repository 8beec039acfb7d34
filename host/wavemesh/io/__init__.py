"""Reading height fields and writing meshes and their companions: the data flow's two ends."""
