"""`voicectl listen`: a local sound source streamed into the recogniser, hands-free."""
