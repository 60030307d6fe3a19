"""`voicectl listen`: the robot's own ear (a microphone, a file or standard input),
its wake phrase and its voice."""
