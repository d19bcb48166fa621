"""The live input timeline: time order and stamp policy for streaming consumers."""
