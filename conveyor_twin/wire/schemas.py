"""ros2msg definition texts of the contract types and their dependencies, as rosbag2 stores them.

A schema in a rosbag2 MCAP file (schema encoding ``ros2msg``) is the text of the root ``.msg``
file followed, for every type it depends on (depth first, each type once), by a separator line of
80 ``=``, a line ``MSG: pkg/Type`` and that type's ``.msg`` text. :func:`full_text` builds that
concatenation; :data:`SCHEMAS` holds it for every type the twin records.

The ``conveyor_twin_msgs`` texts equal ``msg_defs/msg/*.msg`` (a test checks it); the texts of
the standard types are those of the Kilted message packages.
"""

import re
from typing import Dict, List, Tuple

#: Separator between the definitions of a concatenated ros2msg schema (rosbag2, mcap).
SEPARATOR = '=' * 80

_PARTSTATES = (
    '# Pose and velocity of every micro-simulated part at one simulation step, in the cell frame\n'
    '# (x along the main conveying direction, y to the left, z up; REP-103).\n'
    '# Structure of arrays: entry i of every array describes the same part; equal lengths.\n'
    '\n'
    'std_msgs/Header header  # stamp: simulation time of the step; frame_id: cell frame\n'
    'uint64 step             # simulation step index [1] (0 = state after reset)\n'
    'uint32[] id             # unique part id [1] (never 0, never reused within a run)\n'
    'uint16[] part_type      # index of the part type in the cell description [1]\n'
    "float64[] x             # position of the part's centre of mass in the cell frame [m]\n"
    "float64[] y             # position of the part's centre of mass in the cell frame [m]\n"
    'float64[] yaw           # orientation about +z in the cell frame [rad]\n'
    'float64[] vx            # linear velocity along x of the cell frame [m/s]\n'
    'float64[] vy            # linear velocity along y of the cell frame [m/s]\n'
    'float64[] wz            # angular velocity about +z [rad/s]\n'
)

_DENSITYGRID = (
    '# Macro-scale part density on the grid of one macro zone at one simulation step.\n'
    '\n'
    'std_msgs/Header header  # stamp: simulation time of the step; frame_id: cell frame\n'
    'uint64 step             # simulation step index [1]\n'
    'string zone             # name of the zone in the cell description\n'
    'float64 origin_x        # cell-frame x of the grid origin, corner of cell (ix=0, iy=0) [m]\n'
    'float64 origin_y        # cell-frame y of the grid origin, corner of cell (ix=0, iy=0) [m]\n'
    'float64 resolution      # edge length of the square grid cells [m]\n'
    'uint32 nx               # number of cells along x [1]\n'
    'uint32 ny               # number of cells along y [1]\n'
    'float32[] density       # areal part density, row-major, index'
    ' iy*nx+ix, length nx*ny [parts/m^2]\n'
    'float64 total_parts     # integral of density over the grid [parts]\n'
)

_LIGHTBARRIERSTATES = (
    '# State of every light barrier at one simulation step (arrays indexed alike).\n'
    '\n'
    'std_msgs/Header header  # stamp: simulation time of the step; frame_id: cell frame\n'
    'uint64 step             # simulation step index\n'
    'string[] name           # light barrier name from the cell description\n'
    'bool[] blocked          # true while the beam is interrupted\n'
    'uint32[] edge_count     # number of edges (both directions) since the last reset\n'
)

_LIGHTBARRIEREDGE = (
    "# One change of a light barrier's state.\n"
    '\n'
    'std_msgs/Header header  # stamp: interpolated simulation time of the'
    ' edge; frame_id: cell frame\n'
    'string name             # light barrier name from the cell description\n'
    'bool blocked            # true: the beam became interrupted; false: the beam became free\n'
    'uint32 part_id          # id of the micro part causing the edge [1];'
    ' 0: edge from the macro scale\n'
)

#: Request part of ``srv/SpawnParts`` (recorded as the accepted ``spawn_parts`` calls).
_FAULTSTATE = (
    '# The active faults, sent whenever they change (latched: a late joiner gets the latest).\n'
    '\n'
    'std_msgs/Header header      # stamp: simulation time from which this set is in effect\n'
    'uint32[] id                 # one entry per active fault: its id (unique in a run)\n'
    'string[] kind               # fault kind (docs/faults.md)\n'
    'string[] target             # what it acts on (barrier, belt, actuator, source, stream, ...)\n'
    'uint32[] param_count        # number of parameters of each fault, in order\n'
    'string[] param_name         # all parameters, fault after fault\n'
    'float64[] param_value       # their values [SI]\n'
    'string[] part_type          # part type of source_wrong_type; empty otherwise\n'
    'float64[] duration          # cleared after this long [s]; 0: until cleared\n'
    'float64[] since             # simulation time it became active [s]\n'
    'uint32[] injected           # ids injected at this stamp\n'
    'uint32[] cleared            # ids cleared at this stamp\n'
    'string[] cleared_reason     # why each was cleared: request, expired, scenario\n'
    'uint32 total_injected       # faults injected since the start\n'
    'uint32 total_rejected       # fault requests rejected since the start\n'
)

_SPAWNPARTS_REQUEST = (
    'string part_type    # part type name from the cell description\n'
    "float64[] x         # cell-frame x of each part's centre of mass [m]\n"
    "float64[] y         # cell-frame y of each part's centre of mass [m]\n"
    "float64[] yaw       # orientation of each part about +z [rad]\n"
)

#: Request part of ``srv/Reset`` (recorded as the accepted ``reset`` calls).
_RESET_REQUEST = (
    'string cell_file    # path of the cell YAML file; empty: keep the current cell\n'
    'uint64 seed         # random seed for sources and sampling\n'
)

_BELTCOMMAND = (
    "# Set the target speed of one belt (applied ramped by the belt's acceleration limit).\n"
    '\n'
    'string belt     # belt name from the cell description\n'
    "float64 speed   # target surface speed along the belt's conveying direction [m/s]\n"
    'string sender   # who sends it (e.g. the node name), echoed on command_status; may be empty\n'
    "uint32 sequence # the sender's number of this command, echoed on command_status; 0: none\n"
)

_BELTSTATES = (
    '# Commanded and actual speed of every belt (arrays indexed alike).\n'
    '\n'
    'std_msgs/Header header        # stamp: simulation time of the step; frame_id: cell frame\n'
    'string[] name                 # belt name from the cell description\n'
    "float64[] commanded_speed     # last accepted target speed along the belt's direction [m/s]\n"
    "float64[] speed               # actual surface speed along the belt's direction [m/s]\n"
)

_ACTUATORCOMMAND = (
    '# Set the target position of one actuator (pusher, stopper, diverter).\n'
    '\n'
    'string actuator     # actuator name from the cell description\n'
    "float64 position    # target position in the actuator's own unit [m]"
    ' for linear, [rad] for rotary\n'
    'string sender       # who sends it (e.g. the node name), echoed on command_status; may be'
    ' empty\n'
    "uint32 sequence     # the sender's number of this command, echoed on command_status; 0:"
    ' none\n'
)

_ACTUATORSTATES = (
    '# Commanded and actual position of every actuator (arrays indexed alike).\n'
    '\n'
    'std_msgs/Header header          # stamp: simulation time of the step; frame_id: cell frame\n'
    'string[] name                   # actuator name from the cell description\n'
    'float64[] commanded_position    # last accepted target position [m]'
    ' for linear, [rad] for rotary\n'
    'float64[] position              # actual position [m] for linear, [rad] for rotary\n'
)

_HEADER = (
    '# Standard metadata for higher-level stamped data types.\n'
    '# This is generally used to communicate timestamped data\n'
    '# in a particular coordinate frame.\n'
    '\n'
    '# Two-integer timestamp that is expressed as seconds and nanoseconds.\n'
    'builtin_interfaces/Time stamp\n'
    '\n'
    '# Transform frame with which this data is associated.\n'
    'string frame_id\n'
)

_TIME = (
    '# This message communicates ROS Time defined here:\n'
    '# https://design.ros2.org/articles/clock_and_time.html\n'
    '\n'
    '# The seconds component, valid over all int32 values.\n'
    'int32 sec\n'
    '\n'
    '# The nanoseconds component, valid in the range [0, 1e9).\n'
    'uint32 nanosec\n'
)

_CLOCK = (
    '# This message communicates the current time.\n'
    '#\n'
    '# For more information, see https://design.ros2.org/articles/clock_and_time.html.\n'
    'builtin_interfaces/Time clock\n'
)

_DIAGNOSTICARRAY = (
    '# This message is used to send diagnostic information about the state of the robot.\n'
    'std_msgs/Header header # for timestamp\n'
    'DiagnosticStatus[] status # an array of components being reported on\n'
)

_DIAGNOSTICSTATUS = (
    '# This message holds the status of an individual component of the robot.\n'
    '\n'
    '# Possible levels of operations.\n'
    'byte OK=0\n'
    'byte WARN=1\n'
    'byte ERROR=2\n'
    'byte STALE=3\n'
    '\n'
    '# Level of operation enumerated above.\n'
    'byte level\n'
    '# A description of the test/component reporting.\n'
    'string name\n'
    '# A description of the status.\n'
    'string message\n'
    '# A hardware unique string.\n'
    'string hardware_id\n'
    '# An array of values associated with the status.\n'
    'KeyValue[] values\n'
    '\n'
)

_KEYVALUE = (
    '# What to label this value when viewing.\n'
    'string key\n'
    '# A value to track over time.\n'
    'string value\n'
)

_VISUALIZATION_MARKERARRAY = (
    'Marker[] markers\n'
)

_VISUALIZATION_MARKER = (
    '# See:\n'
    '#  - http://www.ros.org/wiki/rviz/DisplayTypes/Marker\n'
    '#  - http://www.ros.org/wiki/rviz/Tutorials/Markers%3A%20Basic%20Shapes\n'
    '#\n'
    '# for more information on using this message with rviz.\n'
    '\n'
    'int32 ARROW=0\n'
    'int32 CUBE=1\n'
    'int32 SPHERE=2\n'
    'int32 CYLINDER=3\n'
    'int32 LINE_STRIP=4\n'
    'int32 LINE_LIST=5\n'
    'int32 CUBE_LIST=6\n'
    'int32 SPHERE_LIST=7\n'
    'int32 POINTS=8\n'
    'int32 TEXT_VIEW_FACING=9\n'
    'int32 MESH_RESOURCE=10\n'
    'int32 TRIANGLE_LIST=11\n'
    'int32 ARROW_STRIP=12\n'
    '\n'
    'int32 ADD=0\n'
    'int32 MODIFY=0\n'
    'int32 DELETE=2\n'
    'int32 DELETEALL=3\n'
    '\n'
    '# Header for timestamp and frame id.\n'
    'std_msgs/Header header\n'
    '# Namespace in which to place the object.\n'
    '# Used in conjunction with id to create a unique name for the object.\n'
    'string ns\n'
    '# Object ID used in conjunction with the namespace for manipulating and deleting'
    ' the object later.\n'
    'int32 id\n'
    '# Type of object.\n'
    'int32 type\n'
    '# Action to take; one of:\n'
    '#  - 0 add/modify an object\n'
    '#  - 1 (deprecated)\n'
    '#  - 2 deletes an object (with the given ns and id)\n'
    '#  - 3 deletes all objects (or those with the given ns if any)\n'
    'int32 action\n'
    '# Pose of the object with respect the frame_id specified in the header.\n'
    'geometry_msgs/Pose pose\n'
    '# Scale of the object; 1,1,1 means default (usually 1 meter square).\n'
    'geometry_msgs/Vector3 scale\n'
    '# Color of the object; in the range: [0.0-1.0]\n'
    'std_msgs/ColorRGBA color\n'
    '# How long the object should last before being automatically deleted.\n'
    '# 0 indicates forever.\n'
    'builtin_interfaces/Duration lifetime\n'
    '# If this marker should be frame-locked, i.e. retransformed into its frame every'
    ' timestep.\n'
    'bool frame_locked\n'
    '\n'
    '# Only used if the type specified has some use for them (eg. POINTS, LINE_STRIP,'
    ' ARROW_STRIP, etc.)\n'
    'geometry_msgs/Point[] points\n'
    '# Only used if the type specified has some use for them (eg. POINTS, LINE_STRIP, etc.)\n'
    '# The number of colors provided must either be 0 or equal to the number of point'
    's provided.\n'
    '# NOTE: alpha is not yet used\n'
    'std_msgs/ColorRGBA[] colors\n'
    '\n'
    '# Texture resource is a special URI that can either reference a texture file in\n'
    '# a format acceptable to (resource retriever)[https://docs.ros.org/en/rolling/p/'
    'resource_retriever/]\n'
    '# or an embedded texture via a string matching the format:\n'
    '#   "embedded://texture_name"\n'
    'string texture_resource\n'
    '# An image to be loaded into the rendering engine as the texture for this marker.\n'
    '# This will be used iff texture_resource is set to embedded.\n'
    'sensor_msgs/CompressedImage texture\n'
    '# Location of each vertex within the texture; in the range: [0.0-1.0]\n'
    'UVCoordinate[] uv_coordinates\n'
    '\n'
    '# Only used for text markers\n'
    'string text\n'
    '\n'
    '# Only used for MESH_RESOURCE markers.\n'
    '# Similar to texture_resource, mesh_resource uses resource retriever to load a mesh.\n'
    '# Optionally, a mesh file can be sent in-message via the mesh_file field. If doing so,\n'
    '# use the following format for mesh_resource:\n'
    '#   "embedded://mesh_name"\n'
    'string mesh_resource\n'
    'MeshFile mesh_file\n'
    'bool mesh_use_embedded_materials\n'
)

_VISUALIZATION_MESHFILE = (
    '# Used to send raw mesh files.\n'
    '\n'
    '# The filename is used for both debug purposes and to provide a file extension\n'
    '# for whatever parser is used.\n'
    'string filename\n'
    '\n'
    '# This stores the raw text of the mesh file.\n'
    'uint8[] data\n'
)

_VISUALIZATION_UVCOORDINATE = (
    '# Location of the pixel as a ratio of the width of a 2D texture.\n'
    '# Values should be in range: [0.0-1.0].\n'
    'float32 u\n'
    'float32 v\n'
)

_SENSOR_COMPRESSEDIMAGE = (
    '# This message contains a compressed image.\n'
    '\n'
    'std_msgs/Header header # Header timestamp should be acquisition time of image\n'
    '                             # Header frame_id should be optical frame of camera\n'
    '                             # origin of frame should be optical center of cameara\n'
    '                             # +x should point to the right in the image\n'
    '                             # +y should point down in the image\n'
    '                             # +z should point into to plane of the image\n'
    '\n'
    'string format                # Specifies the format of the data\n'
    '                             # Acceptable values differ by the image transport used:\n'
    '                             # - compressed_image_transport:\n'
    '                             #     ORIG_PIXFMT; CODEC compressed [COMPRESSED_PIXFMT]\n'
    '                             #   where:\n'
    '                             #   - ORIG_PIXFMT is pixel format of the raw image, i.e.\n'
    '                             #     the content of sensor_msgs/Image/encoding with\n'
    '                             #     values from include/sensor_msgs/image_encodings.h\n'
    '                             #   - CODEC is one of [jpeg, png, tiff]\n'
    '                             #   - COMPRESSED_PIXFMT is only appended for color images\n'
    '                             #     and is the pixel format used by the compression\n'
    '                             #     algorithm. Valid values for jpeg encoding are:\n'
    '                             #     [bgr8, rgb8]. Valid values for png encoding are:\n'
    '                             #     [bgr8, rgb8, bgr16, rgb16].\n'
    '                             #   If the field is empty or does not correspond to the\n'
    '                             #   above pattern, the image is treated as bgr8 or mono8\n'
    '                             #   jpeg image (depending on the number of channels).\n'
    '                             # - compressed_depth_image_transport:\n'
    '                             #     ORIG_PIXFMT; compressedDepth CODEC\n'
    '                             #   where:\n'
    '                             #   - ORIG_PIXFMT is pixel format of the raw image, i.e.\n'
    '                             #     the content of sensor_msgs/Image/encoding with\n'
    '                             #     values from include/sensor_msgs/image_encodings.h\n'
    '                             #     It is usually one of [16UC1, 32FC1].\n'
    '                             #   - CODEC is one of [png, rvl]\n'
    '                             #   If the field is empty or does not correspond to the\n'
    '                             #   above pattern, the image is treated as png image.\n'
    '                             # - Other image transports can store whatever values they\n'
    '                             #   need for successful decoding of the image. Refer to\n'
    '                             #   documentation of the other transports for details.\n'
    '\n'
    'uint8[] data                 # Compressed image buffer\n'
)

_STD_COLORRGBA = (
    'float32 r\n'
    'float32 g\n'
    'float32 b\n'
    'float32 a\n'
)

_GEOMETRY_POINT = (
    '# This contains the position of a point in free space\n'
    'float64 x\n'
    'float64 y\n'
    'float64 z\n'
)

_BUILTIN_DURATION = (
    '# Duration defines a period between two time points.\n'
    '# Messages of this datatype are of ROS Time following this design:\n'
    '# https://design.ros2.org/articles/clock_and_time.html\n'
    '\n'
    '# Seconds component, range is valid over any possible int32 value.\n'
    'int32 sec\n'
    '\n'
    '# Nanoseconds component in the range of [0, 1e9).\n'
    'uint32 nanosec\n'
)

_GEOMETRY_VECTOR3 = (
    '# This represents a vector in free space.\n'
    '\n'
    '# This is semantically different than a point.\n'
    '# A vector is always anchored at the origin.\n'
    '# When a transform is applied to a vector, only the rotational component is applied.\n'
    '\n'
    'float64 x\n'
    'float64 y\n'
    'float64 z\n'
)

_GEOMETRY_POSE = (
    '# A representation of pose in free space, composed of position and orientation.\n'
    '\n'
    'Point position\n'
    'Quaternion orientation\n'
)

_GEOMETRY_QUATERNION = (
    '# This represents an orientation in free space in quaternion form.\n'
    '\n'
    'float64 x 0\n'
    'float64 y 0\n'
    'float64 z 0\n'
    'float64 w 1\n'
)

_PARTTRANSFER = (
    '# Parts that left a cell of a plant through a transfer link, and how far that cell ran.\n'
    "# Published by the link's exit cell on the link's `transfer` topic; the entry cell inserts\n"
    "# each part at step_left + the link's delay (later if its entry is occupied). Structure of\n"
    '# arrays: entry i of every array describes the same part. Poses and velocities are relative\n'
    "# to the link's exit frame (origin at the exit, x along the belt that carries parts there).\n"
    '\n'
    "std_msgs/Header header  # stamp: simulation time of `through`; frame_id: the link's name\n"
    "string link             # the link's name in the plant file\n"
    'uint64 through          # steps the exit cell has completed: every part that left in a\n'
    '                        # step <= through is in this message or an earlier one [1]\n'
    'uint64 first_seq        # number of the first part here in the link; the others follow [1]\n'
    'uint64 held_from        # number of the oldest part the exit still holds (not reported\n'
    '                        # inserted; a restarted entry cell starts from it) [1]\n'
    "uint64 run              # id of the exit cell's run: a restarted exit cell numbers parts\n"
    '                        # and counts steps from 0 again, under another id [1]\n'
    'uint64[] step_left      # step in which the part left the exit cell [1]\n'
    "uint32[] id             # the part's id in the exit cell [1]\n"
    "uint32[] origin_id      # the part's id where it entered the plant [1]\n"
    "uint16[] part_type      # index of the part type in the exit cell's description [1]\n"
    'float64[] x             # position relative to the exit frame [m]\n'
    'float64[] y             # lateral offset relative to the exit frame [m]\n'
    'float64[] yaw           # orientation relative to the exit frame [rad]\n'
    "float64[] vx            # velocity along the exit frame's x [m/s]\n"
    "float64[] vy            # velocity along the exit frame's y [m/s]\n"
    'float64[] wz            # angular velocity about +z [rad/s]\n'
)

_TRANSFERACCEPTED = (
    '# Parts a cell of a plant inserted from a transfer link, and how far that cell has run.\n'
    "# Published by the link's entry cell on the link's `accepted` topic; the exit cell holds\n"
    '# every part until it is reported here, and (for a link with a capacity) counts the room.\n'
    '\n'
    "std_msgs/Header header  # stamp: simulation time of `through`; frame_id: the link's name\n"
    "string link             # the link's name in the plant file\n"
    "uint64 through          # steps the entry cell has completed (in exit_run's steps) [1]\n"
    "uint64 run              # id of the entry cell's current run; another id means it\n"
    '                        # restarted empty [1]\n'
    "bool starting           # the entry has not received the exit's oldest held part yet (a\n"
    '                        # fresh run): the exit sends every part it holds (again)\n'
    "uint64 exit_run         # the exit cell's run whose parts `seq` numbers and in whose steps\n"
    '                        # `through` and `step` count (see exit_run_known) [1]\n'
    'bool exit_run_known     # false: the entry has heard of no run of the exit cell yet\n'
    "bool final              # the entry cell's run has completed its last step: it inserts\n"
    '                        # nothing more, and `seq` has reported every insertion\n'
    'uint64[] seq            # number of each inserted part in the link, ascending [1]\n'
    'uint64[] step           # step in which it was inserted [1]\n'
)

_CELLPROGRESS = (
    '# How far a cell of a plant has run and its part counts: the plant-wide ledger and\n'
    '# progress are built from these (entered = in cells + in links + left + vanished).\n'
    '\n'
    "std_msgs/Header header  # stamp: simulation time of `step`; frame_id: the cell's name\n"
    "string cell             # the cell's name in the plant file\n"
    'uint64 step             # steps completed [1]\n'
    'uint64 end_step         # the step the run ends at (0: no end) [1]\n'
    'bool done               # the cell completed end_step, and every exit heard its entry\n'
    "                        # cell's final insertions: the counts are the run's last\n"
    "uint64 run              # id of the cell's current run [1]\n"
    'float64 entered         # parts that entered through its sources and spawns [parts]\n'
    'float64 in_cell         # parts in the cell now (micro bodies and macro density) [parts]\n'
    'float64 left            # parts that left through its sinks (not links) [parts]\n'
    'float64 vanished        # parts that fell off the line (fault parts_vanish) [parts]\n'
    'string[] exit_link      # the links this cell feeds\n'
    'uint64[] exit_sent      # parts sent into each [1]\n'
    'uint64[] exit_accepted  # of those, parts its entry cell reported inserted [1]\n'
    'uint64[] exit_resent    # parts sent again to a restarted entry cell [1]\n'
    'string[] entry_link     # the links that feed this cell\n'
    'uint64[] entry_inserted # parts inserted from each [1]\n'
    'uint64[] entry_waiting  # parts due and waiting because the entry is occupied [1]\n'
    'uint64[] entry_earlier  # of entry_inserted, parts of earlier runs of the exit cell [1]\n'
    'uint64[] entry_dropped  # parts of earlier exit cell runs received, never inserted [1]\n'
    'float64 step_time_mean_ms  # mean wall time of a step since the start [ms]\n'
    'float64 real_time_factor   # simulated over wall time since the start [1]\n'
    "string state_hash       # SHA-256 of the cell's state and of every part it sent (see docs)\n"
)

#: ``.msg`` texts of the types ``markers`` (visualization_msgs/MarkerArray) needs, as the
#: Kilted message packages ship them (Marker with texture, UV coordinates and mesh file).
_MARKER_TEXTS: Dict[str, str] = {
    'visualization_msgs/msg/MarkerArray': _VISUALIZATION_MARKERARRAY,
    'visualization_msgs/msg/Marker': _VISUALIZATION_MARKER,
    'visualization_msgs/msg/MeshFile': _VISUALIZATION_MESHFILE,
    'visualization_msgs/msg/UVCoordinate': _VISUALIZATION_UVCOORDINATE,
    'sensor_msgs/msg/CompressedImage': _SENSOR_COMPRESSEDIMAGE,
    'std_msgs/msg/ColorRGBA': _STD_COLORRGBA,
    'geometry_msgs/msg/Point': _GEOMETRY_POINT,
    'builtin_interfaces/msg/Duration': _BUILTIN_DURATION,
    'geometry_msgs/msg/Vector3': _GEOMETRY_VECTOR3,
    'geometry_msgs/msg/Pose': _GEOMETRY_POSE,
    'geometry_msgs/msg/Quaternion': _GEOMETRY_QUATERNION,
}

#: ``.msg`` text of every known type, by full type name (``pkg/msg/Type``).
MSG_TEXTS: Dict[str, str] = {
    'conveyor_twin_msgs/msg/PartStates': _PARTSTATES,
    'conveyor_twin_msgs/msg/DensityGrid': _DENSITYGRID,
    'conveyor_twin_msgs/msg/LightBarrierStates': _LIGHTBARRIERSTATES,
    'conveyor_twin_msgs/msg/LightBarrierEdge': _LIGHTBARRIEREDGE,
    'conveyor_twin_msgs/msg/BeltCommand': _BELTCOMMAND,
    'conveyor_twin_msgs/msg/BeltStates': _BELTSTATES,
    'conveyor_twin_msgs/msg/ActuatorCommand': _ACTUATORCOMMAND,
    'conveyor_twin_msgs/msg/ActuatorStates': _ACTUATORSTATES,
    'conveyor_twin_msgs/msg/FaultState': _FAULTSTATE,
    'conveyor_twin_msgs/msg/PartTransfer': _PARTTRANSFER,
    'conveyor_twin_msgs/msg/TransferAccepted': _TRANSFERACCEPTED,
    'conveyor_twin_msgs/msg/CellProgress': _CELLPROGRESS,
    'conveyor_twin_msgs/srv/SpawnParts_Request': _SPAWNPARTS_REQUEST,
    'conveyor_twin_msgs/srv/Reset_Request': _RESET_REQUEST,
    'std_msgs/msg/Header': _HEADER,
    'builtin_interfaces/msg/Time': _TIME,
    'rosgraph_msgs/msg/Clock': _CLOCK,
    'diagnostic_msgs/msg/DiagnosticArray': _DIAGNOSTICARRAY,
    'diagnostic_msgs/msg/DiagnosticStatus': _DIAGNOSTICSTATUS,
    'diagnostic_msgs/msg/KeyValue': _KEYVALUE,
    **_MARKER_TEXTS,
}

#: Type names of the interface package of the contract.
CONTRACT_TYPES: Tuple[str, ...] = tuple(
    name for name in MSG_TEXTS if name.startswith('conveyor_twin_msgs/msg/'))

PRIMITIVES = frozenset((
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16', 'int32',
    'uint32', 'int64', 'uint64', 'string', 'wstring'))

_ARRAY = re.compile(r'\[(<=)?(\d*)\]$')
_BOUNDED_STRING = re.compile(r'^(w?string)<=(\d+)$')


class Field:
    """One field of a ``.msg`` definition (constants are not fields)."""

    __slots__ = ('name', 'base', 'array', 'capacity', 'string_capacity')

    def __init__(self, name: str, base: str, array: str, capacity: int,
                 string_capacity: int) -> None:
        """Describe a field.

        :param name: field name.
        :param base: primitive name (``float64``, ``string``) or full type name
            (``pkg/msg/Type``) of a nested type.
        :param array: ``''`` (single value), ``'fixed'``, ``'bounded'`` or ``'unbounded'``.
        :param capacity: array size (fixed) or upper bound (bounded), else 0.
        :param string_capacity: upper bound of a bounded string, else 0.
        """
        self.name = name
        self.base = base
        self.array = array
        self.capacity = capacity
        self.string_capacity = string_capacity

    def __repr__(self) -> str:
        return f'Field({self.name!r}, {self.base!r}, {self.array!r}, {self.capacity})'


def parse_fields(type_name: str, text: str) -> List[Field]:
    """Return the fields of a ``.msg`` text, in order, without constants and comments.

    :param type_name: full name of the type the text defines (``pkg/msg/Type``), to resolve
        package-relative nested types.
    :param text: ``.msg`` text.
    :raises ValueError: on a line that is not a field or constant definition.
    """
    package = type_name.split('/')[0]
    fields = []
    for raw in text.splitlines():
        line = raw.split('#', 1)[0].strip()
        if not line:
            continue
        parts = line.split(None, 1)
        if len(parts) != 2:
            raise ValueError(f'{type_name}: cannot parse line {raw!r}')
        ftype, rest = parts
        rest = rest.strip()
        if '=' in rest.split()[0] or (len(rest.split()) > 1 and rest.split()[1].startswith('=')):
            continue  # constant
        name = rest.split()[0]
        array, capacity = '', 0
        match = _ARRAY.search(ftype)
        if match:
            ftype = ftype[:match.start()]
            if match.group(1):
                array, capacity = 'bounded', int(match.group(2))
            elif match.group(2):
                array, capacity = 'fixed', int(match.group(2))
            else:
                array = 'unbounded'
        string_capacity = 0
        bounded = _BOUNDED_STRING.match(ftype)
        if bounded:
            ftype, string_capacity = bounded.group(1), int(bounded.group(2))
        if ftype in PRIMITIVES:
            base = ftype
        elif '/' in ftype:
            pkg, name_ = ftype.split('/')[0], ftype.split('/')[-1]
            base = f'{pkg}/msg/{name_}'
        else:
            base = f'{package}/msg/{ftype}'
        fields.append(Field(name, base, array, capacity, string_capacity))
    return fields


def dependencies(type_name: str) -> List[str]:
    """Return the nested types of a type in the order rosbag2 concatenates them.

    rosbag2 (``rosbag2_storage_mcap``) visits the dependencies of each type sorted by name,
    depth first, each type once.

    :param type_name: full type name (``pkg/msg/Type``) present in :data:`MSG_TEXTS`.
    """
    seen: List[str] = []

    def visit(name: str) -> None:
        nested = sorted({f.base for f in parse_fields(name, MSG_TEXTS[name])} - PRIMITIVES,
                        key=_short_name)
        for dep in nested:
            if dep not in seen:
                seen.append(dep)
                visit(dep)

    visit(type_name)
    return seen


def _short_name(type_name: str) -> str:
    """Return ``pkg/Type`` for ``pkg/msg/Type``."""
    pkg, _, name = type_name.split('/')
    return f'{pkg}/{name}'


def full_text(type_name: str) -> str:
    """Return the concatenated ros2msg schema text of a type, as rosbag2 writes it.

    :param type_name: full type name (``pkg/msg/Type``) present in :data:`MSG_TEXTS`.
    :raises KeyError: for an unknown type.
    """
    text = MSG_TEXTS[type_name]
    for dep in dependencies(type_name):
        text += f'\n{SEPARATOR}\nMSG: {_short_name(dep)}\n{MSG_TEXTS[dep]}'
    return text


#: Concatenated schema text of every known type, by full type name.
SCHEMAS: Dict[str, str] = {name: full_text(name) for name in MSG_TEXTS}
