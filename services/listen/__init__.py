"""`voicectl listen`: the robot's own ear, its wake phrase and its voice."""
