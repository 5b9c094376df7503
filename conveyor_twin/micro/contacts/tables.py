"""Column layouts of the contact kernels' tables (shared by broad phase, narrow phase, response).

Every table is a float64 (or int64) NumPy array with one row per item and the columns named
here, so the kernels take only arrays and ints.
"""

# --- model parameter slots (float64 array ``mp``) ---
MP_SLOP = 0           # penetration left uncorrected [m]
MP_CORRECTION = 1     # fraction of the excess penetration removed per substep
MP_STIFFNESS = 2      # penalty spring [N/m]
MP_DAMPING = 3        # penalty damper [N s/m]
MP_DT = 4             # substep [s]
MP_GRAVITY = 5        # [m/s^2]
MP_FLOOR_MU = 6       # friction coefficient off the belts
MP_TRACK = 7          # 1.0: accumulate activities
MP_SPEC_MARGIN = 8    # speculative contacts: gap beyond the closing travel of a substep [m]
MP_SPEC_MAX = 9       # speculative contacts: largest gap recorded [m] (0: touching only)
MP_TOLERANCE = 10     # impulse sweeps end when no increment changed a relative speed more [m/s]
MP_BOUNCE_TOLERANCE = 11  # the same for the restitution sweeps [m/s]
MP_BOUNCE_PASSES = 12     # most restitution sweeps per substep
MP_SWEEP_WORK = 13    # impulse sweeps: contact visits a substep may spend (0: no budget) [-]
MP_MAX_SWEEPS = 14    # impulse sweeps: most per substep, however few the contacts [-]
MP_COLUMNS = 15

# --- activity slots [J] (Rideout and Stein: integral of |power| dt per element class) ---
A_SPRING = 0
A_DAMPER = 1
A_CONTACT_FRICTION = 2
A_BELT = 3
A_INERTIA = 4
A_COLUMNS = 5

# --- static shape table columns (float64, one row per shape) ---
SH_NV = 0
SH_OFF = 1
SH_R = 2
SH_E = 3
SH_MU = 4
SH_XMIN = 5
SH_YMIN = 6
SH_XMAX = 7
SH_YMAX = 8
SH_AX = 9             # first core vertex [m] (segments and pegs: used by the grid binning)
SH_AY = 10
SH_BX = 11            # second core vertex (pegs: the first again)
SH_BY = 12
SH_COLUMNS = 13

# --- actuator state columns (float64, one row per actuator, rewritten every substep) ---
AS_ACTIVE = 0
AS_NV = 1
AS_R = 2
AS_VX = 3             # translation velocity [m/s]
AS_VY = 4
AS_W = 5              # angular velocity about the pivot [rad/s]
AS_PX = 6             # pivot [m]
AS_PY = 7
AS_E = 8
AS_MU = 9
AS_XMIN = 10
AS_YMIN = 11
AS_XMAX = 12
AS_YMAX = 13
AS_COLUMNS = 14

# --- contact record columns (float64 (capacity, CT_COLUMNS)); ``cidx`` (capacity, 2) holds
# the part indices a and b (b = -1: fixed or kinematic body, its velocity in CT_BVX..CT_BW) ---
CT_NX = 0             # unit normal, pointing to a
CT_NY = 1
CT_RAX = 2            # contact point relative to a's centre [m]
CT_RAY = 3
CT_RBX = 4            # relative to b's centre or the kinematic body's pivot [m]
CT_RBY = 5
CT_DEPTH = 6          # penetration at detection [m] (< 0: a speculative contact's gap)
CT_E = 7
CT_MU_S = 8
CT_MU_K = 9
CT_V_T = 10
CT_BVX = 11
CT_BVY = 12
CT_BW = 13
# written by :func:`prepare_contacts` before the sweeps (off the sweeps' dependency chain)
CT_IKN = 14           # 1 / normal effective mass [1/kg]
CT_IKT = 15           # 1 / tangential effective mass [1/kg]
CT_SLOPE = 16         # (mu_k - mu_s) / v_t [s/m]
CT_WA = 17            # position correction: share of a (fraction included) [-]
CT_WB = 18
CT_CNT = 19           # change of the tangential speed per unit normal impulse [1/kg]
CT_KA = 20            # key: id of a (+ 2^40 against a fixed or kinematic body) [-]
CT_KB = 21            # key: 2 (id of b, or the shape's index) + the contact point's index [-]
# written by :func:`prepare_contacts` (the bounce, the warm start) and the impulse sweeps
CT_BOUNCE = 22        # normal separation speed restitution asks for [m/s] (0: none)
CT_LN = 23            # accumulated normal impulse of the substep [N s]
CT_LT = 24            # accumulated tangential impulse [N s]
CT_KN = 25            # normal effective mass's inverse [1/kg] (the sweeps' residual)
CT_TARGET = 26        # least relative normal speed the sweeps allow: min(depth, 0) / h [m/s]
CT_LN0 = 27           # the warm start's normal impulse [N s] (0: none)
CT_COLUMNS = 28

# --- the previous substep's contacts (``prev`` (C + 1, PV_COLUMNS); row C, column 0: count) ---
PV_KA = 0
PV_KB = 1
PV_LN = 2
PV_LT = 3
PV_COLUMNS = 4

# contact records per part slot
CONTACTS_PER_PART = 8
