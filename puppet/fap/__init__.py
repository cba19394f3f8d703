"""The MPEG-4 facial animation parameters themselves: the 68-FAP table and its units, one frame of a
FAP stream, held FAPs, visemes and expressions, and ``Pose``, what the face shows at an instant.
Nothing here knows a face or a file.
"""
