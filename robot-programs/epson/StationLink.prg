' =============================================================================================
' StationLink.prg - the calibration station's robot program for an Epson SCARA (RC700 / RC90 /
' RC800 family, Epson RC+ 7 / 8, SPEL+), register map version 3 (drivers/controller_map.py,
' docs/protocols.md, docs/robot-program.md).
'
' HOW THE PROGRAM SERVES THE STATION
'   The station's driver is a Modbus TCP client of the controller's holding registers. No
'   document in reach (list below) describes a Modbus TCP server in a standard RC700 / RC90
'   controller. Epson documents two remote interfaces instead - the remote Ethernet / RS-232
'   command set ($Login, $Start, $GetVariable, ... [RC5-UG11], [UG-RS232]) and the command words
'   of the Remote Control Reference 8.0 [RCREF80] - and neither speaks Modbus, so either would
'   need a new driver (drivers/ is not ours to change). The PC as Modbus server with the robot
'   as client would likewise need a new driver. So the program keeps the one design that serves
'   the register map unchanged: it is itself the Modbus TCP server, framing Modbus by hand over
'   a SPEL+ TCP/IP port (OpenNet ... As Server, WaitNet, ChkNet, ReadBin, WriteBin [TCP-14.3]).
'   The communication side runs as BACKGROUND TASKS (Function BgMain = task 65, the Modbus server
'   task Xqt'd from it), which Epson documents for "communicating with external devices" and
'   which do not stop at an emergency stop or a safeguard input [UG-BG]. Background tasks may not
'   execute manipulator commands [UG-BG], so the motion side (main, MoveTask, the inverse
'   kinematics, reading the joints) is a normal task. Nothing uses NoEmgAbort any more.
'
' WHAT IT IMPLEMENTS
'   * Modbus TCP on port #NET_PORT: function codes 3 and 4 (read), 6 and 16 (write), exception
'     1 for any other function, 2 for an address outside BASE .. BASE+127 or a PC write to a
'     register the program writes, 3 for a bad count. One client at a time.
'   * Identification (re-published every heartbeat), heartbeat (0.1 s), watchdog on hb_pc, the
'     command handshake with the sequence rule, MOVE_JOINTS, MOVE_CARTESIAN (the controller's own
'     inverse kinematics plus the active correction table by the interpolation rule of
'     docs/protocols.md), STOP, RESET, soft limits checked on what WILL be commanded, e-stop /
'     drive fault / watchdog latching until RESET.
'   * One station per controller (map 3's claim block), served by the heartbeat task (the only
'     writer of the owner): a token in claim_request becomes claim_owner only while claim_owner
'     is 0 and hb_pc is live; the owner's release code (0xFFFFFFFF - token) frees it, and so does
'     hb_pc silent for WATCHDOG_MS; freeing clears the request and the holder's host, PID and
'     since. Every command but STOP whose cmd_token is not claim_owner is refused with
'     NOT_CLAIMED. A token is kept as its two 16-bit words (a Long cannot hold an unsigned 32-bit
'     value), so the release code is 65535 - high word, 65535 - low word: no new built-in.
'     claim_owner is the program's: a PC write to it is refused with exception 2.
'   * The transfer block (served inside the Modbus request that starts it): WRITE_HEADER /
'     WRITE_PAGE with the page CRC-32 checked, READ_HEADER / READ_PAGE, READ_INFO (soft limits,
'     actual pose), READ_{STAGED,ACTIVE,PREVIOUS}_{HEADER,PAGE}. Page CRC-32 = zlib CRC-32
'     (polynomial 0xEDB88320, init and final xor 0xFFFFFFFF) over the page's registers as
'     big-endian bytes, exactly as the map defines it; computed table-driven with the state kept
'     in two 16-bit halves, so no value needs an unsigned 32-bit type.
'   * Staged / active / previous tables, TABLE_STAGE / ACTIVATE / DEACTIVATE / ROLLBACK /
'     DISCARD_PREVIOUS with the slot rules of simulators/controller_tables.py.
'   * All-zero globals are a valid empty state (no table, no latch), because Epson clears
'     Globals whenever a function is started from the Run or Operator window [REF-GLOBAL]; the
'     heartbeat re-publishes the identification registers and rebuilds the CRC table.
'
' WHAT WAS NOT DONE
'   * This program has NOT run on a real controller, nor in the RC+ simulator, and RC+ has not
'     compiled it. It builds and runs, unchanged, in the tests' SPEL+ executor
'     (simulators/epson/), written from the pages and Epson's code listed under SOURCES with the
'     strictest reading where they are silent: `station check` and `station conformance` exit 0
'     against it over loopback (tests/robot_programs/test_epson_station_cli.py), and the line's
'     faults - a client gone mid-request, a half-sent frame, an emergency stop and a restart of
'     main, the motors off, a joint-range stop - are tests (test_epson_faults.py). An executor
'     is not RC+: build it in RC+ first and fix what the compiler says.
'   * One Modbus client at a time (the station); a second connection waits until the first
'     closes or stalls for NET_TIMEOUT_MS.
'   * The controller's own kinematics and any arm calibration set with ArmSet are the "nominal"
'     kinematics here: CORRECTION_STATE defaults to 2 (unknown).
'
' MINIMUM VERSIONS
'   Epson RC+ 7.0 with an RC700 / RC700-A or RC90 controller, or RC+ 8.0 with an RC800: the
'   manual sets the program follows ([UG-BG], [UG-TYPES], [REF-GLOBAL]) are those of RC+ 7 and
'   8. It needs background tasks [UG-BG], the UByte type [UG-TYPES] and Global Static
'   [REF-GLOBAL]; no page read states the first release of each. An older RC+ (5, 6) or
'   controller (RC170, RC180) is not supported: the program follows none of their manuals.
'   Confirm both versions against the release notes of your RC+ before the first build.
'
' WHAT WAS CHECKED: each construct class the program uses and where it is written (document,
'   section; SOURCES below). Where Epson documents nothing - a Modbus TCP server in SPEL+ - the
'   program keeps to constructs Epson's own code uses [EPSON-MODBUS].
'   * Function name (a As T, ...) As T ... Fend, the result by assigning the function's name,
'     Exit Function, calls written f(args) or Call f(args) (never "f a, b"), local declarations
'     "Long a, b" / "UByte buf(7)" at the top of a function: [EPSON-MODBUS] (every function).
'   * OnErr GoTo label with the handler at the end of the function, after Exit Function (no
'     EResume anywhere): [EPSON-MODBUS] (ErrProc in every function), [UG-BG] (errors in
'     background tasks). Err in the handler: Language Reference, not confirmed page by page;
'     ErrAxis: no page (see CONFIRM ON A REAL CONTROLLER).
'   * If ... Then / ElseIf / Else / EndIf, single-line If, Do While ... Loop, Do ... Loop,
'     For ... To ... [Step] ... Next, Exit Do / Exit For, Wait <seconds>: [REF-HALT] (example),
'     [REF-TASKINFO] (example), [EPSON-MODBUS] (Do While ChkNet(port) < 7 ... Wait 0.05 ... Loop,
'     For index = 0 To count - 1 ... Next).
'   * Global Static <type> name(dims), Static on every Global (Globals not Preserve / Static are
'     cleared when a function starts from the Run / Operator window; Epson's library code writes
'     the pair Global NonStatic): [REF-GLOBAL], [EPSON-MODBUS]. At most 100,000 elements per
'     array, 3 dimensions: [REF-GLOBAL], [UG-ARRAYS] (TBuf 96,000, StoreReg 64,032; locals
'     under 2,000).
'   * Types Boolean, UByte (0..255, the ReadBin / WriteBin buffers as in [EPSON-MODBUS]), Integer
'     (16 bit: only loop counters and indices), Long (32 bit: every register value), Double:
'     [UG-TYPES]. A register value (0..65535) is never stored in an Integer.
'   * Identifiers: no SPEL+ keyword or point syntax (Off, Speed, Err, Val, Base, P(...)) names a
'     variable, parameter, function or #define; no local has a global's, function's or
'     #define's name in any case (SPEL+ names are not case-sensitive: Index / index in
'     [EPSON-MODBUS]). #define NAME number: [EPSON-MODBUS] (Modbus.inc's constants).
'   * And / Or / Not on Long words and Booleans, &H literals, /: [EPSON-MODBUS] (address And
'     &HFF, address / &H100, ... And tmoutcnt > 0). Xor, LShift, RShift, Mod (always in
'     parentheses), Int, Abs: Language Reference, not confirmed page by page.
'   * Background tasks: BgMain is task 65 and starts when the project loads; Xqt from it makes
'     background tasks; not stopped by an emergency stop or a safeguard; no manipulator command
'     (Go, Speed, Accel, Motor, Power, Tool, Here, Agl) in them; "any error that occurs in the
'     background task cannot be recovered in AUTO mode" - hence OnErr in ServeConnection and
'     HeartbeatLoop, each called again by an endless loop: [UG-BG]. Program lines at most 512
'     characters: [UG-RULES].
'   * One register image, three writers (main, the heartbeat, the Modbus server): every access
'     to Regs that a Modbus read must see whole (a 32-bit value's two words; ack_seq with the
'     done_seq / error_seq after it) happens while the task holds SyncLock REGS_LOCK, and the
'     server copies a read's registers under the same lock, so one Modbus read never returns a
'     half-written update. Tasks are switched preemptively; without the lock a read of the
'     status block could show error_seq = n beside the old ack_seq (found by `station
'     conformance`; 7 of 1178 commands over loopback). No task waits (Wait, a motion, the
'     network) while it holds the lock: StopMotion releases it while the arm stops, and a
'     TABLE_STAGE's checks and copy run without it (StageTable keeps its own running CRC).
'     [REF-SYNCLOCK]; held IDs are released when a task ends (RC+ 6.0 and later), so an
'     emergency stop that aborts main frees the lock.
'   * Xqt funcName, task numbers (normal 1-32, background 65-80): [REF-HALT], [REF-TASKINFO].
'     TaskInfo(MAIN_TASK, 3): main is up only in state 1 (running) or 2 (waiting); MoveTask is
'     Xqt'd from main, never from the background side: [REF-TASKINFO].
'   * OpenNet #p As Server, WaitNet #p [, timeout], ChkNet(p) (the bytes waiting; < 0: not
'     connected / not open), CloseNet #p, ReadBin #p, buf(), n, WriteBin #p, buf(), n, ports
'     201-216: [EPSON-MODBUS] (OpenNet As Client, WaitNet #port, 3.0, ChkNet(port) <= -3,
'     ReadBin #port, bufHeader(), 7, WriteBin #port, bufSend(), 12), [TCP-14.3]. A receive waits
'     at most NET_TIMEOUT_MS in Wait 0.01 steps, as [EPSON-MODBUS] bounds its receive.
'   * Motor On, Power High, Tool n in main before the first motion; Speed / Accel whole
'     percents 1..100 ([RCREF80] Command 1): cmd_speed (0.1 % steps) below 1 % is refused
'     BAD_COMMAND, others round down (never faster than asked). Motors off: NOT_READY, nothing
'     latched.
'   * Go JA(j1, j2, j3, j4) Till MemSw(bit) = On, TillOn, MemOn / MemOff: [REF-JA], [REF-TILL]
'     (MemSw is one of the functions a Till condition may use). P900 = XY(x, y, z, u) /L or /R,
'     PAgl, Agl, CX / CY / CZ / CU (Here), DegToRad / RadToDeg: SPEL+ Language Reference, not
'     confirmed page by page; the executor runs them as the station's protocol needs.
'   * Roll and pitch of MOVE_CARTESIAN: refused UNREACHABLE (a SCARA sets neither).
'   * The logic was traced against simulators/controller_server.py, controller_tables.py,
'     controller_claim.py and drivers/correction_table.py; tests/test_robot_programs.py checks
'     every map constant and the CRC polynomial halves against drivers/controller_map.py and zlib.
'
' CONFIRM ON A REAL CONTROLLER (the executor follows the pages; no controller confirmed them)
'   * Global Static: that a Global declared Static keeps its value when main is started from the
'     Run / Operator window, and that the arrays fit the controller's memory for globals
'     (about 160,000 Long elements) [REF-GLOBAL]. The tables and the claim depend on it.
'   * TaskInfo(task, 3) state numbers: 1 running, 2 waiting, 3 halted, 5 ended by an error, -1
'     not executing, as read on [REF-TASKINFO]; and that a background task may call TaskInfo.
'   * The Motor function: `Motor = Off` tests the motors' state in main (no page read shows
'     Motor used as a function; only the Motor On / Off statement).
'   * ErrAxis: that it returns the axis of the last error (0 for none) inside an OnErr handler;
'     no page for it was found. Without it error_joint of a DRIVE_FAULT is wrong, not the code.
'   * That main's SyncLock REGS_LOCK is released when an emergency stop aborts main, as
'     [REF-SYNCLOCK] says for a task that is finished (RC+ 6.0 and later); otherwise the server
'     and the heartbeat would wait on it until main runs again.
'   * That the emergency stop aborts main and not BgMain [UG-BG] (the program reports the running
'     motion as ESTOP and refuses commands NOT_READY until main runs again).
'   * ReadBin / WriteBin "#port, buf(), n", ChkNet's return values and WaitNet's timeout beyond
'     [EPSON-MODBUS] and the reprint [TCP-14.3]; whether ChkNet turns negative when the client
'     closes the connection (the executor keeps counting the bytes waiting: the 2 s receive
'     timeout ends the connection either way).
'   * The precedence of Mod among + and - (every Mod here is parenthesised) and how RC+ stores a
'     Double into an integer variable (the program stores only whole values: Int, FloorD).
'
' INSTALL AND CONFIGURE
'   1. Add this file to an Epson RC+ project and build. Enable background tasks in the
'      controller preferences so that BgMain starts when the project loads [UG-BG]; start main
'      (Auto mode or the Run window) for the motion side.
'   2. Controller TCP/IP port #201 (NET_PORT): server, local port 502 (or the port of
'      [devices] controller), no terminator.
'   3. Set the #defines below: REG_BASE (= [devices] controller_register_base), WORD_ORDER_BIG
'      (1 = "big", 0 = "little"), WATCHDOG_MS, TOOL_NO (a Tool defined as the probe head K),
'      CORRECTION_STATE, MAIN_TASK (main's task number, 1 when started normally),
'      NET_TIMEOUT_MS, and the soft limits in InitConfig (station units: rad, rad, mm, rad).
'   4. The station's robot file must describe the robot as Epson does: J1, J2, J4 in Epson's
'      zero and sign (deg in SPEL+, rad on the wire), J3 in mm, base frame = Epson's robot
'      coordinates, the elbow flag +1 = J2 > 0.
'   5. With the robot parked at [conformance].park_joints run `station conformance CONFIG`
'      before the first calibration.
'
' SOURCES (download.epson.biz/robots/ww/data/html/... is Epson's online manual set)
'   [EPSON-MODBUS] Epson's own SPEL+ code, a Modbus TCP client: Epson-Robots/rcplus-extensions,
'                  samples/rcplus-custom/VanguardModelPFScrewdriver/VanguardModelPFScrewdriver/
'                  Libraries/Source/VGD_PF/Modbus.prg (and Modbus.inc).
'   [REF-HALT]     SPEL+ Language Reference, "Halt Statement", SPEL/en/030/030-120/030-120-010/
'                  030-120-010-010.html (syntax, task numbers, example program).
'   [REF-TASKINFO] SPEL+ Language Reference, "TaskInfo Function", SPEL/en/030/030-230/
'                  030-230-010/030-230-010-050.html (task types Normal / NoPause / NoEmgAbort,
'                  index 3 = -1 when not executing, If / Else / EndIf example).
'   [REF-TILL]     SPEL+ Language Reference, "Till", SPEL/sc/030/030-230/030-230-010/
'                  030-230-010-170.html (condition functions incl. MemSw; TillOn / Stat).
'   [REF-JA]       SPEL+ Language Reference, "JA Function", SPEL_RC800/ja/030/030-140/
'                  030-140-010/030-140-010-130.html and SPEL/tc/... same path.
'   [REF-SYNCLOCK] SPEL+ Language Reference (RC800), "SyncLock Statement" and "SyncUnlock
'                  Statement", SPEL_RC800/en/030/030-220/030-220-010/030-220-010-600.html and
'                  -610.html (syncID 0..63, SyncUnlock's page 1..63; a second SyncLock of
'                  the same ID is an error; only the task that locked an ID unlocks it; RC+ 6.0
'                  and later release the IDs of a task that ends).
'   [REF-GLOBAL]   SPEL+ Language Reference (RC800), "Global", SPEL_RC800/ja/030/030-110/
'                  030-110-010/030-110-010-040.html (types, 100,000 elements, Preserve 4,000,
'                  Globals cleared when a function starts from the Run / Operator window).
'   [UG-TYPES]     Epson RC+ User's Guide, "Data types", UsersGuide/ja/070/070-010/
'                  070-010-050.html.
'   [UG-ARRAYS]    Epson RC+ User's Guide, "Arrays", UsersGuide/ja/070/070-010/070-010-070/
'                  070-010-070-060.html.
'   [UG-BG]        Epson RC+ User's Guide, "Primary features of background task" and "Holding
'                  background task", UsersGuide/en/070/070-010/070-010-230/070-010-230-010.html
'                  and -030.html.
'   [UG-RULES]     Epson RC+ User's Guide, "Program rules", UsersGuide/en/080/080-010/
'                  080-010-030/080-010-030-010.html.
'   [UG-RS232]     Epson RC+ User's Guide, "Remote RS232 Command", UsersGuide/en/130/130-010/
'                  130-010-030/130-010-030-050.html.
'   [RC5-UG11]     EPSON RC+ 5.0 (Ver.5.4) User's Guide Rev.4, ch. 11 "Remote Control",
'                  pp. 263-275 (remote Ethernet commands; copy at manualshelf.com, rc170).
'   [RCREF80]      Epson RC+ 8.0 Remote Control Reference, RemoteControl_Ref80/.../090-010-010-020
'                  ("Command 1", PTP accel / decel in %) and 090-310-010-120 ("Command 2111").
'   [TCP-14.3]     "14.3 TCP/IP commands" of Epson's manual as reprinted in Chinese at
'                  blog.csdn.net/pinbodexiaozhu/article/details/43565205 (secondary source).
' =============================================================================================

' ---------------- configuration (the integrator sets these) ---------------------------------
#define REG_BASE 0
#define WORD_ORDER_BIG 1
#define WATCHDOG_MS 1000
#define N_JOINTS 4
#define NET_PORT 201
' a Modbus frame whose rest does not arrive within this time drops the connection
#define NET_TIMEOUT_MS 2000
#define TOOL_NO 1
#define CORRECTION_STATE 2
#define STOP_BIT 0
' the task number of main (the motion side), for TaskInfo [REF-TASKINFO]
#define MAIN_TASK 1
' the SyncLock ID that guards the register image Regs [REF-SYNCLOCK]: a free ID 1..63
' (SyncLock's page allows 0..63, SyncUnlock's 1..63)
#define REGS_LOCK 1
' the running CRC each user keeps (CrcHi / CrcLo index)
#define CRC_XFER 0
#define CRC_STAGE 1

' ---------------- register map 3 (tests/test_robot_programs.py keeps these true) -------------
#define MAP_VERSION 3
#define WINDOW_SIZE 128
#define PAGE_DATA_REGISTERS 58
#define PAGE_VALUES 29
#define MAX_TABLE_VALUES 32000
#define MAX_PAGES 1104
#define TABLE_FORMAT_VERSION 2
#define TABLE_HEADER_REGISTERS 30
#define ORDER_CHECK_VALUE 1
#define R_HB_PC 0
#define R_HB_ROBOT 1
#define R_MAP_VERSION 2
#define R_N_JOINTS 3
#define R_WATCHDOG_MS 4
#define R_CORRECTION_STATE 5
#define R_ORDER_CHECK 6
#define R_CMD_CODE 8
#define R_CMD_SEQ 9
#define R_CMD_ELBOW 10
#define R_CMD_SPEED 11
#define R_CMD_TARGET 12
#define R_CMD_TOKEN 24
#define R_CLAIM_REQUEST 26
#define R_CLAIM_OWNER 28
#define R_CLAIM_HOST 30
#define R_CLAIM_PID 32
#define R_CLAIM_SINCE 34
#define R_ACK_SEQ 36
#define R_DONE_SEQ 37
#define R_ERROR_SEQ 38
#define R_ERROR_CODE 39
#define R_STATUS 40
#define R_ERROR_JOINT 41
#define R_ERROR_BOUND 42
#define R_XFER_ACK 43
#define R_XFER_ERROR 44
#define R_ACT_JOINTS 45
#define R_TABLE_STAGED_CRC 57
#define R_TABLE_ACTIVE_CRC 59
#define R_TABLE_PREVIOUS_CRC 61
#define R_XFER_SEQ 63
#define R_XFER_OP 64
#define R_PAGE_INDEX 65
#define R_PAGE_LEN 66
#define R_PAGE_CRC 67
#define R_PAGE_DATA 69
#define H_TABLE_FORMAT 0
#define H_TABLE_N_AXES 1
#define H_TABLE_SHAPE 2
#define H_TABLE_START 6
#define H_TABLE_STEP 14
#define H_TABLE_PERIODIC 22
#define H_TABLE_N_JOINTS 23
#define H_TABLE_N_CONFIGS 24
#define H_TABLE_N_VALUES 25
#define H_TABLE_CRC 27
#define H_TABLE_VALUE_SCALE_EXP 29
#define INFO_SOFT_LIMITS 0
#define INFO_ACT_POSE 1
#define C_NONE 0
#define C_MOVE_JOINTS 1
#define C_MOVE_CARTESIAN 2
#define C_STOP 3
#define C_RESET 4
#define C_TABLE_STAGE 10
#define C_TABLE_ACTIVATE 11
#define C_TABLE_DEACTIVATE 12
#define C_TABLE_ROLLBACK 13
#define C_TABLE_DISCARD_PREVIOUS 14
#define X_NONE 0
#define X_WRITE_HEADER 1
#define X_WRITE_PAGE 2
#define X_READ_HEADER 3
#define X_READ_PAGE 4
#define X_READ_INFO 5
#define X_READ_STAGED_HEADER 6
#define X_READ_STAGED_PAGE 7
#define X_READ_ACTIVE_HEADER 8
#define X_READ_ACTIVE_PAGE 9
#define X_READ_PREVIOUS_HEADER 10
#define X_READ_PREVIOUS_PAGE 11
#define CS_NONE 0
#define CS_VENDOR 1
#define CS_UNKNOWN 2
#define E_NONE 0
#define E_SOFT_LIMIT 1
#define E_UNREACHABLE 2
#define E_ESTOP 3
#define E_DRIVE_FAULT 4
#define E_BAD_COMMAND 5
#define E_SEQUENCE_ERROR 6
#define E_TABLE_CRC_MISMATCH 7
#define E_TABLE_NOT_STAGED 8
#define E_TABLE_SHAPE_INVALID 9
#define E_TARGET_OUTSIDE_TABLE 10
#define E_WATCHDOG_TIMEOUT 11
#define E_NOT_READY 12
#define E_MOTION_ABORTED 13
#define E_NO_PREVIOUS_TABLE 14
#define E_PAGE_CRC_MISMATCH 15
#define E_PAGE_INVALID 16
#define E_NOT_CLAIMED 17
' 18: the map's code for a controller with its own collision check; this program has none
#define E_COLLISION 18
#define S_READY 1
#define S_MOVING 2
#define S_IN_POSITION 4
#define S_ERROR 8
#define S_ESTOP 16
#define S_TABLE_ACTIVE 32
#define S_TABLE_STAGED 64
#define S_TABLE_PREVIOUS 128
' slots: index into SlotBuf
#define SLOT_STAGED 0
#define SLOT_ACTIVE 1
#define SLOT_PREVIOUS 2

' ---------------- global state ----------------------------------------------------------
' Every Global is Static: starting main from the Run / Operator window (after every emergency
' stop) clears the Globals not declared Preserve or Static [REF-GLOBAL], which would drop the
' active correction table and the claim while the background side keeps serving. (Preserve
' keeps values over a power cycle and holds only 4,000 bytes [REF-GLOBAL]; the tables do not
' fit.) Epson's own library code names the qualifier pair: Global NonStatic [EPSON-MODBUS].
' Every Global is zero after a start from the Run / Operator window [REF-GLOBAL]; zero is a
' valid state for all of them (no table, no latch, CRC table rebuilt by the heartbeat).
' the window image (offsets 0..127)
Global Static Long Regs(127)
' the command block as it arrived (offsets 8..25), and that a write covered cmd_seq
Global Static Long CmdSnap(17)
Global Static Boolean CmdWritten
' the transfer store: header page and value pages as the PC wrote them (0 = no such page)
Global Static Long StoreHdr(29)
Global Static Integer StoreHdrLen
Global Static Long StoreReg(1103, 57)
Global Static Integer StoreLen(1103)
' three table buffers (raw i32 values, canonical header page); SlotRef(slot) = buffer + 1,
' 0 = no table in that slot
Global Static Long TBuf(2, 31999)
Global Static Long THdr(2, 29)
Global Static Integer SlotRef(2)
' CRC-32 table in two 16-bit halves, and the running CRCs: one for the server's transfer pages
' (CRC_XFER), one for main's TABLE_STAGE (CRC_STAGE), which runs without the lock beside it
Global Static Long CrcTabHi(255), CrcTabLo(255)
Global Static Long CrcHi(1), CrcLo(1)
' robot state
Global Static Double SoftLo(3), SoftHi(3)
Global Static Long Status
Global Static Boolean Latched, Moving, InPosition, WdFired, MainUp
Global Static Long LastSeq, MotionSeq, HbRobot, LastXfer, HbIdle
' the token of the station that holds the controller, as its high and low word (0, 0: free)
Global Static Long OwnHi, OwnLo
' errors the background tasks handled (a client gone mid-frame), for the integrator
Global Static Long NetErrors, HbErrors
' whether the server / the heartbeat holds REGS_LOCK, for their error handlers: a task that
' locks an ID it holds gets an error [REF-SYNCLOCK]
Global Static Boolean SrvHolds, HbHolds
Global Static Double Tq(3), Dq(3)
' the controller's pose of the tool (x, y, z mm, u deg), kept by main for READ_INFO
Global Static Double ActPose(3)
Global Static Integer MoveSpeedPct
' 0 running, 1 arrived, 2 stopped by STOP (Till), 3 error
Global Static Integer MoveResult
' the controller's error number and axis of a failed move (ErrAxis: 0 when no axis)
Global Static Long MoveErrNo, MoveErrAxis
' Modbus frame buffers: UByte (0..255) for ReadBin / WriteBin, as Epson's Modbus client declares
' them [EPSON-MODBUS] (Byte is -128..127 [UG-TYPES])
Global Static UByte Rx(299), Tx(299)

' ---------------- the communication side: background tasks [UG-BG] -----------------------
' BgMain starts as task 65 when the controller loads the project; the Modbus server task
' Xqt'd from it is a background task too. Neither executes a manipulator command.
Function BgMain
    CrcInit()
    PublishIdent()
    LastXfer = Regs(R_XFER_SEQ)
    Xqt ModbusServer
    Heartbeat()
Fend

' the identification registers (re-written every heartbeat)
Function PublishIdent
    Regs(R_MAP_VERSION) = MAP_VERSION
    Regs(R_N_JOINTS) = N_JOINTS
    Regs(R_WATCHDOG_MS) = WATCHDOG_MS
    Regs(R_CORRECTION_STATE) = CORRECTION_STATE
    PutI32(R_ORDER_CHECK, ORDER_CHECK_VALUE)
Fend

' every 0.1 s, also while moving: hb_robot, identification, the watchdog on hb_pc (counted in
' heartbeat cycles), and whether main (the motion side) still runs [REF-TASKINFO]
Function Heartbeat
    Do
        Call HeartbeatLoop()
        ' an error (none is expected) must not end the heartbeat: counted, then served on
        HbErrors = HbErrors + 1
        If HbErrors > 65535 Then HbErrors = 0
    Loop
Fend

Function HeartbeatLoop
    Long hbPcLast, st
    OnErr GoTo HbErr
    hbPcLast = Regs(R_HB_PC)
    HbIdle = 0
    Do
        SyncLock REGS_LOCK
        HbHolds = True
        HbRobot = HbRobot + 1
        If HbRobot > 65535 Then HbRobot = 0
        Regs(R_HB_ROBOT) = HbRobot
        If CrcTabLo(1) = 0 Then CrcInit()
        PublishIdent()
        If Regs(R_HB_PC) <> hbPcLast Then
            hbPcLast = Regs(R_HB_PC)
            HbIdle = 0
        ElseIf HbIdle < 100000 Then
            HbIdle = HbIdle + 1
        EndIf
        If Moving And HbIdle * 100 > WATCHDOG_MS Then WdFired = True
        ServeClaim()
        ' main is up only while it runs (1) or waits (2) [REF-TASKINFO]: halted (3), paused or
        ' ended by an error (5) does not answer commands
        st = TaskInfo(MAIN_TASK, 3)
        If st = 1 Or st = 2 Then
            MainUp = True
        Else
            MainUp = False
        EndIf
        ' main no longer runs (an emergency stop or an abort ended it): the motion it ran is over
        If Moving And Not MainUp And Not Latched Then
            Moving = False
            Refuse(MotionSeq, E_ESTOP, 0, 0)
        EndIf
        PublishStatus()
        HbHolds = False
        SyncUnlock REGS_LOCK
        Wait 0.1
    Loop
HbErr:
    If HbHolds Then
        HbHolds = False
        SyncUnlock REGS_LOCK
    EndIf
Fend

' ---------------- the claim block: one station per controller ---------------------------
' once per heartbeat (the only writer of OwnHi / OwnLo): the watchdog, a release, a grant;
' claim_owner is published last, so that a station that reads it 0 finds the rest cleared
Function ServeClaim
    Long rqHi, rqLo
    Boolean held
    rqHi = U32Hi(R_CLAIM_REQUEST)
    rqLo = U32Lo(R_CLAIM_REQUEST)
    held = False
    If OwnHi <> 0 Or OwnLo <> 0 Then held = True
    If held And HbIdle * 100 > WATCHDOG_MS Then
        FreeClaim()
    ElseIf held And rqHi = 65535 - OwnHi And rqLo = 65535 - OwnLo Then
        FreeClaim()
    ElseIf Not held And HbIdle * 100 <= WATCHDOG_MS Then
        If rqHi <> 0 Or rqLo <> 0 Then
            OwnHi = rqHi
            OwnLo = rqLo
        EndIf
    EndIf
    PutWords(R_CLAIM_OWNER, OwnHi, OwnLo)
Fend

' freeing clears the request and the holder's host, PID and since: no stale request is granted
' later, no stale holder named
Function FreeClaim
    OwnHi = 0
    OwnLo = 0
    PutWords(R_CLAIM_REQUEST, 0, 0)
    PutWords(R_CLAIM_HOST, 0, 0)
    PutWords(R_CLAIM_PID, 0, 0)
    PutWords(R_CLAIM_SINCE, 0, 0)
Fend

' whether the command block's cmd_token (at snapshot offset a) is the holder's token
Function TokenIsOwner(a As Integer) As Boolean
    Long tHi, tLo
    TokenIsOwner = False
    If OwnHi = 0 And OwnLo = 0 Then Exit Function
    If WORD_ORDER_BIG = 1 Then
        tHi = CmdSnap(a)
        tLo = CmdSnap(a + 1)
    Else
        tHi = CmdSnap(a + 1)
        tLo = CmdSnap(a)
    EndIf
    If tHi = OwnHi And tLo = OwnLo Then TokenIsOwner = True
Fend

' ---------------- words and scaled integers --------------------------------------------
Function U32Hi(ofs As Integer) As Long
    If WORD_ORDER_BIG = 1 Then
        U32Hi = Regs(ofs)
    Else
        U32Hi = Regs(ofs + 1)
    EndIf
Fend

Function U32Lo(ofs As Integer) As Long
    If WORD_ORDER_BIG = 1 Then
        U32Lo = Regs(ofs + 1)
    Else
        U32Lo = Regs(ofs)
    EndIf
Fend

' signed 32-bit value from its words; (hi - 65536) * 65536 + lo stays in range when negative
Function JoinI32(hi As Long, lo As Long) As Long
    If hi >= 32768 Then
        JoinI32 = (hi - 65536) * 65536 + lo
    Else
        JoinI32 = hi * 65536 + lo
    EndIf
Fend

Function HiWord(v As Long) As Long
    HiWord = RShift(v, 16) And &HFFFF
Fend

Function LoWord(v As Long) As Long
    LoWord = v And &HFFFF
Fend

Function PutWords(ofs As Integer, hi As Long, lo As Long)
    If WORD_ORDER_BIG = 1 Then
        Regs(ofs) = hi
        Regs(ofs + 1) = lo
    Else
        Regs(ofs) = lo
        Regs(ofs + 1) = hi
    EndIf
Fend

Function PutI32(ofs As Integer, v As Long)
    PutWords(ofs, HiWord(v), LoWord(v))
Fend

Function PutI16(ofs As Integer, v As Long)
    If v < 0 Then
        Regs(ofs) = v + 65536
    Else
        Regs(ofs) = v
    EndIf
Fend

' floor for a Double, whatever Int does with negative numbers
Function FloorD(x As Double) As Double
    Double f
    f = Int(x)
    If f > x Then f = f - 1
    FloorD = f
Fend

' value -> scaled count, rounded
Function Counts(x As Double, perUnit As Double) As Long
    Counts = FloorD(x * perUnit + 0.5)
Fend

' ---------------- CRC-32 (zlib / ISO-HDLC), table-driven in 16-bit halves ----------------
' The page CRC of the map: CRC-32 with the reflected polynomial 0xEDB88320, start 0xFFFFFFFF,
' final xor 0xFFFFFFFF, over each register high byte first (= zlib.crc32 of the big-endian
' bytes). CrcHi(who) / CrcLo(who) are its high and low 16 bits, who = CRC_XFER or CRC_STAGE.
Function CrcInit
    Integer n, k
    Long hi, lo, c
    For n = 0 To 255
        hi = 0
        lo = n
        For k = 1 To 8
            c = lo And 1
            lo = RShift(lo, 1) Or LShift(hi And 1, 15)
            hi = RShift(hi, 1)
            If c = 1 Then
                hi = hi Xor &HEDB8
                lo = lo Xor &H8320
            EndIf
        Next
        CrcTabHi(n) = hi
        CrcTabLo(n) = lo
    Next
Fend

Function CrcStart(who As Integer)
    CrcHi(who) = &HFFFF
    CrcLo(who) = &HFFFF
Fend

Function CrcByte(who As Integer, b As Long)
    Integer idx
    idx = (CrcLo(who) And &HFF) Xor b
    CrcLo(who) = (RShift(CrcLo(who), 8) Or LShift(CrcHi(who) And &HFF, 8)) Xor CrcTabLo(idx)
    CrcHi(who) = RShift(CrcHi(who), 8) Xor CrcTabHi(idx)
Fend

' one register, high byte first
Function CrcWord(who As Integer, w As Long)
    CrcByte(who, RShift(w, 8) And &HFF)
    CrcByte(who, w And &HFF)
Fend

Function CrcEnd(who As Integer)
    CrcHi(who) = CrcHi(who) Xor &HFFFF
    CrcLo(who) = CrcLo(who) Xor &HFFFF
Fend

' ---------------- status and results ---------------------------------------------------
' the buffer a slot holds, -1 for none
Function SlotOf(slot As Integer) As Integer
    SlotOf = SlotRef(slot) - 1
Fend

Function PublishStatus
    Long s
    s = 0
    If Not Latched Then s = s + S_READY
    If Moving Then s = s + S_MOVING
    If InPosition Then s = s + S_IN_POSITION
    If Latched Then s = s + S_ERROR
    If (Status And S_ESTOP) <> 0 And Latched Then s = s + S_ESTOP
    If SlotRef(SLOT_ACTIVE) <> 0 Then s = s + S_TABLE_ACTIVE
    If SlotRef(SLOT_STAGED) <> 0 Then s = s + S_TABLE_STAGED
    If SlotRef(SLOT_PREVIOUS) <> 0 Then s = s + S_TABLE_PREVIOUS
    Status = s
    Regs(R_STATUS) = s
    PublishCrc(SLOT_STAGED, R_TABLE_STAGED_CRC)
    PublishCrc(SLOT_ACTIVE, R_TABLE_ACTIVE_CRC)
    PublishCrc(SLOT_PREVIOUS, R_TABLE_PREVIOUS_CRC)
Fend

' the slot's whole-table CRC (its header's, checked at TABLE_STAGE), 0 for an empty slot
Function PublishCrc(slot As Integer, ofs As Integer)
    Integer b
    b = SlotOf(slot)
    If b < 0 Then
        PutWords(ofs, 0, 0)
    ElseIf WORD_ORDER_BIG = 1 Then
        PutWords(ofs, THdr(b, H_TABLE_CRC), THdr(b, H_TABLE_CRC + 1))
    Else
        PutWords(ofs, THdr(b, H_TABLE_CRC + 1), THdr(b, H_TABLE_CRC))
    EndIf
Fend

' details first, the sequence number last; latching codes latch
Function Refuse(seq As Long, code As Integer, joint As Integer, bound As Integer)
    Regs(R_ERROR_CODE) = code
    PutI16(R_ERROR_JOINT, joint)
    PutI16(R_ERROR_BOUND, bound)
    If code = E_ESTOP Or code = E_DRIVE_FAULT Or code = E_WATCHDOG_TIMEOUT Then
        Latched = True
        If code = E_ESTOP Then Status = Status Or S_ESTOP
        PublishStatus()
    EndIf
    Regs(R_ERROR_SEQ) = seq
Fend

Function ReportDone(seq As Long)
    Regs(R_DONE_SEQ) = seq
Fend

' ---------------- the motion side: main, a normal task ----------------------------------
Function main
    InitConfig()
    ' the motion side switches the motors on as Epson's examples do before the first motion
    Motor On
    Power High
    Tool TOOL_NO
    MoveResult = 1
    Moving = False
    InPosition = True
    CmdWritten = False
    LastSeq = Regs(R_CMD_SEQ)
    WriteActJoints()
    PublishStatus()
    CommandLoop()
Fend

' soft limits in station units (rad, rad, mm, rad): set them for your robot
Function InitConfig
    SoftLo(0) = DegToRad(-130)
    SoftHi(0) = DegToRad(130)
    SoftLo(1) = DegToRad(-145)
    SoftHi(1) = DegToRad(145)
    SoftLo(2) = -200
    SoftHi(2) = 0
    SoftLo(3) = DegToRad(-360)
    SoftHi(3) = DegToRad(360)
Fend

' act_joints (J3 in mm, the others deg -> rad) and the pose READ_INFO reports
Function WriteActJoints
    Integer j
    Double v
    For j = 0 To 5
        v = 0
        If j < N_JOINTS Then
            v = Agl(j + 1)
            If j <> 2 Then v = DegToRad(v)
        EndIf
        PutI32(R_ACT_JOINTS + 2 * j, Counts(v, 1000000))
    Next
    ActPose(0) = CX(Here)
    ActPose(1) = CY(Here)
    ActPose(2) = CZ(Here)
    ActPose(3) = CU(Here)
Fend

' one move, started by Xqt from Dispatch; STOP sets memory bit STOP_BIT, which the Till
' condition watches [REF-TILL]. A controller error in the move (the robot's own joint range, a
' servo error) continues at MoveErr, as Epson's own code handles errors ([EPSON-MODBUS]: OnErr
' GoTo, the handler at the end of the function): the error number and the axis ErrAxis names
' go to main, which reports them; no EResume.
Function MoveTask
    OnErr GoTo MoveErr
    Speed MoveSpeedPct
    Accel MoveSpeedPct, MoveSpeedPct
    Go JA(RadToDeg(Tq(0)), RadToDeg(Tq(1)), Tq(2), RadToDeg(Tq(3))) Till MemSw(STOP_BIT) = On
    If TillOn Then
        MoveResult = 2
    Else
        MoveResult = 1
    EndIf
    Exit Function
MoveErr:
    MoveErrNo = Err
    MoveErrAxis = ErrAxis
    MoveResult = 3
Fend

' stop the running motion and wait until the motion task has ended. Called from CommandLoop,
' which holds REGS_LOCK: released while the arm stops, so that the server and the heartbeat go
' on meanwhile (nothing here has written a register yet)
Function StopMotion
    MemOn STOP_BIT
    SyncUnlock REGS_LOCK
    Do While MoveResult = 0 And Not EStopOn
        Wait 0.01
    Loop
    SyncLock REGS_LOCK
    Moving = False
    WriteActJoints()
    PublishStatus()
Fend

' the command loop: motion results, then a new command block, every 2 ms; act_joints about
' every 0.1 s
Function CommandLoop
    Long seq, expected, code
    Integer tick
    tick = 0
    Do
        ' main ends by an error or an abort only: the controller then releases the lock
        SyncLock REGS_LOCK
        If Moving And EStopOn And Not Latched Then
            Moving = False
            WriteActJoints()
            Refuse(MotionSeq, E_ESTOP, 0, 0)
        ElseIf Moving And WdFired Then
            StopMotion()
            Refuse(MotionSeq, E_WATCHDOG_TIMEOUT, 0, 0)
        ElseIf Moving And MoveResult = 1 Then
            Moving = False
            InPosition = True
            WriteActJoints()
            PublishStatus()
            ReportDone(MotionSeq)
        ElseIf Moving And MoveResult = 3 Then
            ' the controller's error with the axis it names (ErrAxis, 0 = none, as the map's
            ' error_joint); the motors off mid-move count as a drive fault too
            Moving = False
            WriteActJoints()
            Refuse(MotionSeq, E_DRIVE_FAULT, MoveErrAxis, 0)
        EndIf
        If CmdWritten Then
            CmdWritten = False
            seq = CmdSnap(R_CMD_SEQ - R_CMD_CODE)
            If seq <> LastSeq Then
                expected = (LastSeq Mod 65535) + 1
                LastSeq = seq
                code = CmdSnap(0)
                Regs(R_ACK_SEQ) = seq
                If seq <> expected Then
                    Refuse(seq, E_SEQUENCE_ERROR, 0, 0)
                Else
                    Dispatch(seq, code)
                EndIf
            EndIf
        EndIf
        tick = tick + 1
        If tick >= 50 Then
            tick = 0
            WriteActJoints()
        EndIf
        SyncUnlock REGS_LOCK
        Wait 0.002
    Loop
Fend

Function SnapI32(ofs As Integer) As Long
    Integer a
    a = ofs - R_CMD_CODE
    If WORD_ORDER_BIG = 1 Then
        SnapI32 = JoinI32(CmdSnap(a), CmdSnap(a + 1))
    Else
        SnapI32 = JoinI32(CmdSnap(a + 1), CmdSnap(a))
    EndIf
Fend

' one command (If / ElseIf: no Select ... Send, whose page was not found)
Function Dispatch(seq As Long, code As Long)
    Long elbow, spd
    Integer j, ec, bound
    Double pose(5)
    If code = C_STOP Then
        If Moving Then
            StopMotion()
            Refuse(MotionSeq, E_MOTION_ABORTED, 0, 0)
        EndIf
        ReportDone(seq)
        Exit Function
    EndIf
    ' STOP is obeyed from anyone; every other command only from the holder of the controller
    If Not TokenIsOwner(R_CMD_TOKEN - R_CMD_CODE) Then
        Refuse(seq, E_NOT_CLAIMED, 0, 0)
        Exit Function
    EndIf
    ' only STOP while a motion runs
    If Moving Then
        Refuse(seq, E_BAD_COMMAND, 0, 0)
        Exit Function
    EndIf
    elbow = CmdSnap(R_CMD_ELBOW - R_CMD_CODE)
    If elbow >= 32768 Then elbow = elbow - 65536
    spd = CmdSnap(R_CMD_SPEED - R_CMD_CODE)
    If code = C_RESET Then
        Latched = False
        Status = Status And Not S_ESTOP
        Regs(R_ERROR_CODE) = E_NONE
        PutI16(R_ERROR_JOINT, 0)
        PutI16(R_ERROR_BOUND, 0)
        PublishStatus()
        ReportDone(seq)
    ElseIf code = C_MOVE_JOINTS Or code = C_MOVE_CARTESIAN Then
        If Latched Then
            Refuse(seq, E_NOT_READY, 0, 0)
            Exit Function
        EndIf
        If spd < 1 Or spd > 1000 Then
            Refuse(seq, E_BAD_COMMAND, 0, 0)
            Exit Function
        EndIf
        If code = C_MOVE_JOINTS Then
            For j = 0 To N_JOINTS - 1
                Tq(j) = SnapI32(R_CMD_TARGET + 2 * j) * 0.000001
            Next
        Else
            If elbow <> 1 And elbow <> -1 Then
                Refuse(seq, E_BAD_COMMAND, 0, 0)
                Exit Function
            EndIf
            For j = 0 To 5
                pose(j) = SnapI32(R_CMD_TARGET + 2 * j) * 0.000001
            Next
            ' a SCARA cannot set roll or pitch: refused, not ignored
            If Abs(pose(3)) > 0.000001 Or Abs(pose(4)) > 0.000001 Then
                Refuse(seq, E_UNREACHABLE, 0, 0)
                Exit Function
            EndIf
            If Not NominalIK(pose(0), pose(1), pose(2), pose(5), elbow) Then
                Refuse(seq, E_UNREACHABLE, 0, 0)
                Exit Function
            EndIf
            If SlotRef(SLOT_ACTIVE) <> 0 Then
                ec = Interpolate(SlotOf(SLOT_ACTIVE), pose(0), pose(1), pose(2), pose(5), elbow)
                If ec <> E_NONE Then
                    Refuse(seq, ec, 0, 0)
                    Exit Function
                EndIf
                For j = 0 To N_JOINTS - 1
                    Tq(j) = Tq(j) + Dq(j)
                Next
            EndIf
        EndIf
        ' the limit check on what WILL be commanded; a NaN fails it too
        For j = 0 To N_JOINTS - 1
            If Not (SoftLo(j) <= Tq(j) And Tq(j) <= SoftHi(j)) Then
                bound = 1
                If Tq(j) < SoftLo(j) Then bound = -1
                Refuse(seq, E_SOFT_LIMIT, j + 1, bound)
                Exit Function
            EndIf
        Next
        ' cmd_speed is 0.1 % steps: Speed and Accel take whole percents 1..100, so a command
        ' slower than 1 % is refused rather than run up to 10 times faster; others round down
        ' (never faster than asked)
        If spd < 10 Then
            Refuse(seq, E_BAD_COMMAND, 0, 0)
            Exit Function
        EndIf
        ' the motors are off (after an emergency stop, or switched off): not ready, not latched;
        ' the operator switches them on (Motor On in main's start)
        If Motor = Off Then
            Refuse(seq, E_NOT_READY, 0, 0)
            Exit Function
        EndIf
        MoveSpeedPct = Int(spd / 10)
        If MoveSpeedPct > 100 Then MoveSpeedPct = 100
        MoveResult = 0
        WdFired = False
        MotionSeq = seq
        Moving = True
        InPosition = False
        PublishStatus()
        MemOff STOP_BIT
        Xqt MoveTask
    ElseIf code = C_TABLE_STAGE Then
        ' the checks, the CRC and the copy of a 32,000-value table take seconds: StageTable runs
        ' without REGS_LOCK (it takes it for the slot switch), so the server and the heartbeat
        ' go on meanwhile. It reads the transfer store, which the station does not write while
        ' it waits for this answer.
        SyncUnlock REGS_LOCK
        ec = StageTable()
        SyncLock REGS_LOCK
        PublishStatus()
        If ec <> E_NONE Then
            Refuse(seq, ec, 0, 0)
        Else
            ReportDone(seq)
        EndIf
    ElseIf code = C_TABLE_ACTIVATE Or code = C_TABLE_DEACTIVATE Or code = C_TABLE_ROLLBACK Or code = C_TABLE_DISCARD_PREVIOUS Then
        ec = SwitchTables(code)
        PublishStatus()
        If ec <> E_NONE Then
            Refuse(seq, ec, 0, 0)
        Else
            ReportDone(seq)
        EndIf
    Else
        ' also NONE (0) and unknown codes
        Refuse(seq, E_BAD_COMMAND, 0, 0)
    EndIf
Fend

' the controller's own inverse kinematics of (x, y, z mm, yaw rad) in the configuration whose J2
' has the sign of elbow; the joints in Tq (station units). False: not reachable. Each hand is
' tried in HandIK, whose error handler answers False (no EResume).
Function NominalIK(x As Double, y As Double, z As Double, yaw As Double, elbow As Long) As Boolean
    NominalIK = True
    If HandIK(x, y, z, yaw, elbow, 1) Then Exit Function
    If HandIK(x, y, z, yaw, elbow, 2) Then Exit Function
    NominalIK = False
Fend

' hand 1: /L, 2: /R; True when the point is reachable in that hand and its J2 has elbow's sign
Function HandIK(x As Double, y As Double, z As Double, yaw As Double, elbow As Long, hand As Integer) As Boolean
    Integer j
    Double j2
    OnErr GoTo IkErr
    HandIK = False
    If hand = 1 Then
        P900 = XY(x, y, z, RadToDeg(yaw)) /L
    Else
        P900 = XY(x, y, z, RadToDeg(yaw)) /R
    EndIf
    ' PAgl fails (to IkErr) when the point cannot be reached
    j2 = PAgl(P900, 2)
    If (elbow = 1 And j2 > 0) Or (elbow = -1 And j2 < 0) Then
        For j = 0 To N_JOINTS - 1
            Tq(j) = PAgl(P900, j + 1)
            If j <> 2 Then Tq(j) = DegToRad(Tq(j))
        Next
        HandIK = True
    EndIf
    Exit Function
IkErr:
    HandIK = False
Fend

' ---------------- the correction table ------------------------------------------------------
Function HdrU32(b As Integer, ofs As Integer) As Long
    If WORD_ORDER_BIG = 1 Then
        HdrU32 = JoinI32(THdr(b, ofs), THdr(b, ofs + 1))
    Else
        HdrU32 = JoinI32(THdr(b, ofs + 1), THdr(b, ofs))
    EndIf
Fend

Function StoreI32(ofs As Integer) As Long
    If WORD_ORDER_BIG = 1 Then
        StoreI32 = JoinI32(StoreHdr(ofs), StoreHdr(ofs + 1))
    Else
        StoreI32 = JoinI32(StoreHdr(ofs + 1), StoreHdr(ofs))
    EndIf
Fend

' TABLE_STAGE: the stored header checked as CorrectionTableData.decode_header and TableAxis do,
' every value page 0 .. ceil(n/29)-1 stored and n values long together, the whole-table CRC-32
' over the values as big-endian bytes; then the table goes into a free buffer as the staged one
Function StageTable As Integer
    Integer nAxes, i, k, b, nPages, used
    Long nValues, nJoints, nConfigs, prodShape, total, wantHi, wantLo, st, sp, hi, lo, v
    StageTable = E_TABLE_SHAPE_INVALID
    If StoreHdrLen <> TABLE_HEADER_REGISTERS Then Exit Function
    If StoreHdr(H_TABLE_FORMAT) <> TABLE_FORMAT_VERSION Then Exit Function
    ' -8 as an i16 word
    If StoreHdr(H_TABLE_VALUE_SCALE_EXP) <> 65528 Then Exit Function
    nAxes = StoreHdr(H_TABLE_N_AXES)
    If nAxes < 1 Or nAxes > 4 Then Exit Function
    prodShape = 1
    For i = 0 To nAxes - 1
        st = StoreI32(H_TABLE_START + 2 * i)
        sp = StoreI32(H_TABLE_STEP + 2 * i)
        If Abs(st) >= 2000000000 Or Abs(sp) >= 2000000000 Or sp <= 0 Then Exit Function
        If StoreHdr(H_TABLE_SHAPE + i) < 1 Then Exit Function
        prodShape = prodShape * StoreHdr(H_TABLE_SHAPE + i)
        If prodShape > MAX_TABLE_VALUES Then Exit Function
    Next
    nJoints = StoreHdr(H_TABLE_N_JOINTS)
    nConfigs = StoreHdr(H_TABLE_N_CONFIGS)
    If nConfigs < 1 Or nConfigs > 2 Or nJoints < 1 Or nJoints > 6 Then Exit Function
    nValues = StoreI32(H_TABLE_N_VALUES)
    If nValues <> nConfigs * prodShape * nJoints Or nValues > MAX_TABLE_VALUES Then Exit Function
    If nJoints <> N_JOINTS Then Exit Function
    nPages = Int((nValues + PAGE_VALUES - 1) / PAGE_VALUES)
    total = 0
    For k = 0 To nPages - 1
        If StoreLen(k) = 0 Then Exit Function
        total = total + StoreLen(k)
    Next
    If total <> 2 * nValues Then Exit Function
    ' first pass: the CRC over the values as big-endian two's-complement bytes
    CrcStart(CRC_STAGE)
    For k = 0 To nPages - 1
        For i = 0 To StoreLen(k) - 1 Step 2
            If WORD_ORDER_BIG = 1 Then
                CrcWord(CRC_STAGE, StoreReg(k, i))
                CrcWord(CRC_STAGE, StoreReg(k, i + 1))
            Else
                CrcWord(CRC_STAGE, StoreReg(k, i + 1))
                CrcWord(CRC_STAGE, StoreReg(k, i))
            EndIf
        Next
    Next
    CrcEnd(CRC_STAGE)
    If WORD_ORDER_BIG = 1 Then
        wantHi = StoreHdr(H_TABLE_CRC)
        wantLo = StoreHdr(H_TABLE_CRC + 1)
    Else
        wantHi = StoreHdr(H_TABLE_CRC + 1)
        wantLo = StoreHdr(H_TABLE_CRC)
    EndIf
    If CrcHi(CRC_STAGE) <> wantHi Or CrcLo(CRC_STAGE) <> wantLo Then
        StageTable = E_TABLE_CRC_MISMATCH
        Exit Function
    EndIf
    ' second pass: into the staged slot's buffer, or one no slot uses. The staged slot is empty
    ' while its buffer is rewritten, so no read (its CRC, a slot read) sees half a table
    SyncLock REGS_LOCK
    b = SlotOf(SLOT_STAGED)
    SlotRef(SLOT_STAGED) = 0
    SyncUnlock REGS_LOCK
    If b < 0 Then
        For b = 0 To 2
            used = 0
            If SlotOf(SLOT_ACTIVE) = b Or SlotOf(SLOT_PREVIOUS) = b Then used = 1
            If used = 0 Then Exit For
        Next
    EndIf
    v = 0
    For k = 0 To nPages - 1
        For i = 0 To StoreLen(k) - 1 Step 2
            If WORD_ORDER_BIG = 1 Then
                hi = StoreReg(k, i)
                lo = StoreReg(k, i + 1)
            Else
                hi = StoreReg(k, i + 1)
                lo = StoreReg(k, i)
            EndIf
            TBuf(b, v) = JoinI32(hi, lo)
            v = v + 1
        Next
    Next
    ' the header as CorrectionTableData.header_registers writes it: unused axes 0
    For i = 0 To TABLE_HEADER_REGISTERS - 1
        THdr(b, i) = StoreHdr(i)
    Next
    For i = nAxes To 3
        THdr(b, H_TABLE_SHAPE + i) = 0
        THdr(b, H_TABLE_START + 2 * i) = 0
        THdr(b, H_TABLE_START + 2 * i + 1) = 0
        THdr(b, H_TABLE_STEP + 2 * i) = 0
        THdr(b, H_TABLE_STEP + 2 * i + 1) = 0
    Next
    THdr(b, H_TABLE_PERIODIC) = StoreHdr(H_TABLE_PERIODIC) And (LShift(1, nAxes) - 1)
    SyncLock REGS_LOCK
    SlotRef(SLOT_STAGED) = b + 1
    SyncUnlock REGS_LOCK
    StageTable = E_NONE
Fend

' the slot rules of simulators/controller_tables.py TableSlots.switch (SlotRef: buffer + 1,
' 0 = none)
Function SwitchTables(code As Long) As Integer
    Integer t
    SwitchTables = E_NONE
    If code = C_TABLE_ACTIVATE Then
        If SlotRef(SLOT_STAGED) = 0 Then
            SwitchTables = E_TABLE_NOT_STAGED
            Exit Function
        EndIf
        ' activating over none keeps the previous table (the one a deactivation set aside)
        If SlotRef(SLOT_ACTIVE) <> 0 Then SlotRef(SLOT_PREVIOUS) = SlotRef(SLOT_ACTIVE)
        SlotRef(SLOT_ACTIVE) = SlotRef(SLOT_STAGED)
        SlotRef(SLOT_STAGED) = 0
    ElseIf code = C_TABLE_DISCARD_PREVIOUS Then
        SlotRef(SLOT_PREVIOUS) = 0
    ElseIf code = C_TABLE_DEACTIVATE Then
        If SlotRef(SLOT_ACTIVE) <> 0 Then
            SlotRef(SLOT_PREVIOUS) = SlotRef(SLOT_ACTIVE)
            SlotRef(SLOT_ACTIVE) = 0
        EndIf
    ElseIf code = C_TABLE_ROLLBACK Then
        If SlotRef(SLOT_PREVIOUS) = 0 Then
            SwitchTables = E_NO_PREVIOUS_TABLE
            Exit Function
        EndIf
        t = SlotRef(SLOT_ACTIVE)
        SlotRef(SLOT_ACTIVE) = SlotRef(SLOT_PREVIOUS)
        SlotRef(SLOT_PREVIOUS) = t
    EndIf
Fend

' The interpolation rule of docs/protocols.md (CorrectionTableData.interpolate) on buffer b at
' the target (x, y, z, yaw): Dq(0..n_joints-1) in rad or mm. E_TARGET_OUTSIDE_TABLE when a
' non-periodic axis with more than one node does not hold the coordinate (tolerance 1e-6 node).
' The result goes to the global Dq() (no ByRef array parameter).
Function Interpolate(b As Integer, x As Double, y As Double, z As Double, yaw As Double, elbow As Long) As Integer
    Integer nAxes, nJoints, nConfigs, cfg, k, j, corner, hiBit, periodic
    Long cnt(3), i0(3), i1(3), idx
    Double u, t(3), w, pt(3), start, stp
    pt(0) = x
    pt(1) = y
    pt(2) = z
    pt(3) = yaw
    nAxes = THdr(b, H_TABLE_N_AXES)
    nJoints = THdr(b, H_TABLE_N_JOINTS)
    nConfigs = THdr(b, H_TABLE_N_CONFIGS)
    periodic = THdr(b, H_TABLE_PERIODIC)
    cfg = 1
    If elbow = 1 Or nConfigs = 1 Then cfg = 0
    For k = 0 To nAxes - 1
        cnt(k) = THdr(b, H_TABLE_SHAPE + k)
        start = HdrU32(b, H_TABLE_START + 2 * k) * 0.000001
        stp = HdrU32(b, H_TABLE_STEP + 2 * k) * 0.000001
        u = (pt(k) - start) / stp
        If (RShift(periodic, k) And 1) = 1 Then
            ' u mod count in [0, count), node count-1 interpolates towards node 0
            u = u - cnt(k) * FloorD(u / cnt(k))
            i0(k) = FloorD(u)
            If i0(k) > cnt(k) - 1 Then i0(k) = cnt(k) - 1
            t(k) = u - i0(k)
            i1(k) = (i0(k) + 1) Mod cnt(k)
        ElseIf cnt(k) = 1 Then
            i0(k) = 0
            i1(k) = 0
            t(k) = 0
        Else
            If Not (-0.000001 <= u And u <= cnt(k) - 1 + 0.000001) Then
                Interpolate = E_TARGET_OUTSIDE_TABLE
                Exit Function
            EndIf
            If u < 0 Then u = 0
            If u > cnt(k) - 1 Then u = cnt(k) - 1
            i0(k) = FloorD(u)
            If i0(k) > cnt(k) - 2 Then i0(k) = cnt(k) - 2
            t(k) = u - i0(k)
            i1(k) = i0(k) + 1
        EndIf
    Next
    For j = 0 To nJoints - 1
        Dq(j) = 0
    Next
    For corner = 0 To LShift(1, nAxes) - 1
        w = 1
        ' flat index in C order: value[cfg][node_0]..[node_{n-1}][joint]
        idx = cfg
        For k = 0 To nAxes - 1
            hiBit = RShift(corner, k) And 1
            If hiBit = 1 Then
                w = w * t(k)
                idx = idx * cnt(k) + i1(k)
            Else
                w = w * (1 - t(k))
                idx = idx * cnt(k) + i0(k)
            EndIf
        Next
        If w <> 0 Then
            For j = 0 To nJoints - 1
                Dq(j) = Dq(j) + w * (TBuf(b, idx * nJoints + j) * 0.00000001)
            Next
        EndIf
    Next
    Interpolate = E_NONE
Fend

' ---------------- the transfer block (called by ModbusServer inside the request) -------------
Function PageOut(n As Long)
    Long i
    CrcStart(CRC_XFER)
    For i = 0 To n - 1
        CrcWord(CRC_XFER, Regs(R_PAGE_DATA + i))
    Next
    CrcEnd(CRC_XFER)
    For i = n To PAGE_DATA_REGISTERS - 1
        Regs(R_PAGE_DATA + i) = 0
    Next
    Regs(R_PAGE_LEN) = n
    PutWords(R_PAGE_CRC, CrcHi(CRC_XFER), CrcLo(CRC_XFER))
Fend

Function ServeTransfer
    Long op, k, n, i, j, b, slot, nValues, first, count
    Long ec
    Double v
    op = Regs(R_XFER_OP)
    k = Regs(R_PAGE_INDEX)
    n = Regs(R_PAGE_LEN)
    ec = E_NONE
    If op = X_WRITE_HEADER Or op = X_WRITE_PAGE Then
        If n > PAGE_DATA_REGISTERS Then
            ec = E_PAGE_INVALID
        Else
            CrcStart(CRC_XFER)
            For i = 0 To n - 1
                CrcWord(CRC_XFER, Regs(R_PAGE_DATA + i))
            Next
            CrcEnd(CRC_XFER)
            If CrcHi(CRC_XFER) <> U32Hi(R_PAGE_CRC) Or CrcLo(CRC_XFER) <> U32Lo(R_PAGE_CRC) Then
                ec = E_PAGE_CRC_MISMATCH
            ElseIf op = X_WRITE_HEADER Then
                If k <> 0 Or n <> TABLE_HEADER_REGISTERS Then
                    ec = E_PAGE_INVALID
                Else
                    ' a header page starts a new table: the stored value pages are dropped
                    For i = 0 To n - 1
                        StoreHdr(i) = Regs(R_PAGE_DATA + i)
                    Next
                    StoreHdrLen = n
                    For i = 0 To MAX_PAGES - 1
                        StoreLen(i) = 0
                    Next
                EndIf
            ElseIf k >= MAX_PAGES Or n = 0 Or (n Mod 2) <> 0 Then
                ec = E_PAGE_INVALID
            Else
                For i = 0 To n - 1
                    StoreReg(k, i) = Regs(R_PAGE_DATA + i)
                Next
                StoreLen(k) = n
            EndIf
        EndIf
    ElseIf op = X_READ_HEADER Then
        If k <> 0 Or StoreHdrLen = 0 Then
            ec = E_PAGE_INVALID
        Else
            For i = 0 To StoreHdrLen - 1
                Regs(R_PAGE_DATA + i) = StoreHdr(i)
            Next
            PageOut(StoreHdrLen)
        EndIf
    ElseIf op = X_READ_PAGE Then
        If k >= MAX_PAGES Then
            ec = E_PAGE_INVALID
        ElseIf StoreLen(k) = 0 Then
            ec = E_PAGE_INVALID
        Else
            For i = 0 To StoreLen(k) - 1
                Regs(R_PAGE_DATA + i) = StoreReg(k, i)
            Next
            PageOut(StoreLen(k))
        EndIf
    ElseIf op = X_READ_INFO And k = INFO_SOFT_LIMITS Then
        For j = 0 To 5
            If j < N_JOINTS Then
                PutI32(R_PAGE_DATA + 4 * j, Counts(SoftLo(j), 1000000))
                PutI32(R_PAGE_DATA + 4 * j + 2, Counts(SoftHi(j), 1000000))
            Else
                PutI32(R_PAGE_DATA + 4 * j, 0)
                PutI32(R_PAGE_DATA + 4 * j + 2, 0)
            EndIf
        Next
        PageOut(24)
    ElseIf op = X_READ_INFO And k = INFO_ACT_POSE Then
        ' the controller's pose of tool TOOL_NO as main last read it (this runs in a background
        ' task, which executes no manipulator command); a SCARA's roll and pitch are 0
        PutI32(R_PAGE_DATA, Counts(ActPose(0), 1000000))
        PutI32(R_PAGE_DATA + 2, Counts(ActPose(1), 1000000))
        PutI32(R_PAGE_DATA + 4, Counts(ActPose(2), 1000000))
        PutI32(R_PAGE_DATA + 6, 0)
        PutI32(R_PAGE_DATA + 8, 0)
        PutI32(R_PAGE_DATA + 10, Counts(DegToRad(ActPose(3)), 1000000))
        PageOut(12)
    ElseIf op >= X_READ_STAGED_HEADER And op <= X_READ_PREVIOUS_PAGE Then
        ' the table in a slot, regenerated as the PC sent it: staged 6/7, active 8/9, previous 10/11
        slot = Int((op - X_READ_STAGED_HEADER) / 2)
        b = SlotOf(slot)
        If b < 0 Then
            ec = E_PAGE_INVALID
        ElseIf ((op - X_READ_STAGED_HEADER) Mod 2) = 0 Then
            If k <> 0 Then
                ec = E_PAGE_INVALID
            Else
                For i = 0 To TABLE_HEADER_REGISTERS - 1
                    Regs(R_PAGE_DATA + i) = THdr(b, i)
                Next
                PageOut(TABLE_HEADER_REGISTERS)
            EndIf
        Else
            nValues = HdrU32(b, H_TABLE_N_VALUES)
            first = k * PAGE_VALUES
            If first >= nValues Then
                ec = E_PAGE_INVALID
            Else
                count = nValues - first
                If count > PAGE_VALUES Then count = PAGE_VALUES
                For i = 0 To count - 1
                    PutI32(R_PAGE_DATA + 2 * i, TBuf(b, first + i))
                Next
                PageOut(2 * count)
            EndIf
        EndIf
    Else
        ec = E_PAGE_INVALID
    EndIf
    ' the answer, the number last
    Regs(R_XFER_ERROR) = ec
    Regs(R_XFER_ACK) = Regs(R_XFER_SEQ)
Fend


' ---------------- Modbus TCP server (a background task) ---------------------------------
' ChkNet(port) without "#", as in [TCP-14.3]: the bytes waiting, or < 0 when the connection is
' gone (-1 open but not connected, -2 another task uses the port, -3 not open).
Function RecvBytes(n As Integer) As Boolean
    Integer tmo
    RecvBytes = False
    ' a half-sent frame must not hold the only connection: give up after NET_TIMEOUT_MS, as
    ' Epson's Modbus client bounds its waits with Wait 0.05 steps [EPSON-MODBUS]
    tmo = 0
    Do While ChkNet(NET_PORT) < n
        If ChkNet(NET_PORT) < 0 Then Exit Function
        If tmo * 10 >= NET_TIMEOUT_MS Then Exit Function
        tmo = tmo + 1
        Wait 0.01
    Loop
    ReadBin #NET_PORT, Rx(), n
    RecvBytes = True
Fend

Function SendBytes(n As Integer)
    WriteBin #NET_PORT, Tx(), n
Fend

' MBAP header (transaction id, protocol 0, length, unit id) + the PDU already in Tx(7..)
Function Reply(tid As Long, unit As Long, pduLen As Long)
    Tx(0) = RShift(tid, 8) And &HFF
    Tx(1) = tid And &HFF
    Tx(2) = 0
    Tx(3) = 0
    Tx(4) = RShift(pduLen + 1, 8) And &HFF
    Tx(5) = (pduLen + 1) And &HFF
    Tx(6) = unit
    SendBytes(7 + pduLen)
Fend

' a Modbus exception response (function code + 0x80, exception code)
Function MbException(tid As Long, unit As Long, fc As Long, code As Long)
    Tx(7) = fc Or &H80
    Tx(8) = code
    Reply(tid, unit, 2)
Fend

' offsets the PC may write: all but hb_robot .. order_check, claim_owner and ack_seq ..
' table_previous_crc
Function PcMayWrite(ofs As Long) As Boolean
    PcMayWrite = True
    If ofs >= R_HB_ROBOT And ofs <= R_ORDER_CHECK + 1 Then PcMayWrite = False
    If ofs >= R_CLAIM_OWNER And ofs <= R_CLAIM_OWNER + 1 Then PcMayWrite = False
    If ofs >= R_ACK_SEQ And ofs <= R_TABLE_PREVIOUS_CRC + 1 Then PcMayWrite = False
Fend

' Epson's guide: an error in a background task cannot be recovered in AUTO mode, so every
' communication error (a client gone mid-reply: WriteBin fails) goes to NetErr, which closes the
' port and serves the next connection [UG-BG], [EPSON-MODBUS] (OnErr GoTo in every function)
Function ModbusServer
    Do
        Call ServeConnection()
    Loop
Fend

Function ServeConnection
    Long tid, unit, fc, addr, cnt, lenField, ofs, wval, i
    Boolean bad
    OnErr GoTo NetErr
    If ChkNet(NET_PORT) > -3 Then CloseNet #NET_PORT
    OpenNet #NET_PORT As Server
    WaitNet #NET_PORT
        Do
            If Not RecvBytes(7) Then Exit Do
            tid = Rx(0) * 256 + Rx(1)
            lenField = Rx(4) * 256 + Rx(5)
            unit = Rx(6)
            If lenField < 2 Or lenField > 254 Then Exit Do
            If Not RecvBytes(lenField - 1) Then Exit Do
            fc = Rx(0)
            addr = Rx(1) * 256 + Rx(2)
            cnt = Rx(3) * 256 + Rx(4)
            ofs = addr - REG_BASE
            If fc = 3 Or fc = 4 Then
                If cnt < 1 Or cnt > 125 Then
                    MbException(tid, unit, fc, 3)
                ElseIf ofs < 0 Or ofs + cnt > WINDOW_SIZE Then
                    MbException(tid, unit, fc, 2)
                Else
                    Tx(7) = fc
                    Tx(8) = 2 * cnt
                    ' one read sees one state of the image: copied under the lock, sent after
                    SyncLock REGS_LOCK
                    SrvHolds = True
                    For i = 0 To cnt - 1
                        Tx(9 + 2 * i) = RShift(Regs(ofs + i), 8) And &HFF
                        Tx(10 + 2 * i) = Regs(ofs + i) And &HFF
                    Next
                    SrvHolds = False
                    SyncUnlock REGS_LOCK
                    Reply(tid, unit, 2 + 2 * cnt)
                EndIf
            ElseIf fc = 6 Then
                ' the register's value is in the count field's bytes
                wval = cnt
                If ofs < 0 Or ofs >= WINDOW_SIZE Then
                    MbException(tid, unit, fc, 2)
                ElseIf Not PcMayWrite(ofs) Then
                    MbException(tid, unit, fc, 2)
                Else
                    SyncLock REGS_LOCK
                    SrvHolds = True
                    Regs(ofs) = wval
                    AfterWrite(ofs, 1)
                    SrvHolds = False
                    SyncUnlock REGS_LOCK
                    For i = 0 To 4
                        Tx(7 + i) = Rx(i)
                    Next
                    Reply(tid, unit, 5)
                EndIf
            ElseIf fc = 16 Then
                If cnt < 1 Or cnt > 123 Or Rx(5) <> 2 * cnt Then
                    MbException(tid, unit, fc, 3)
                ElseIf ofs < 0 Or ofs + cnt > WINDOW_SIZE Then
                    MbException(tid, unit, fc, 2)
                Else
                    bad = False
                    For i = 0 To cnt - 1
                        If Not PcMayWrite(ofs + i) Then bad = True
                    Next
                    If bad Then
                        MbException(tid, unit, fc, 2)
                    Else
                        SyncLock REGS_LOCK
                        SrvHolds = True
                        For i = 0 To cnt - 1
                            Regs(ofs + i) = Rx(6 + 2 * i) * 256 + Rx(7 + 2 * i)
                        Next
                        AfterWrite(ofs, cnt)
                        SrvHolds = False
                        SyncUnlock REGS_LOCK
                        For i = 0 To 4
                            Tx(7 + i) = Rx(i)
                        Next
                        Reply(tid, unit, 5)
                    EndIf
                EndIf
            Else
                MbException(tid, unit, fc, 1)
            EndIf
        Loop
    CloseNet #NET_PORT
    Exit Function
NetErr:
    If SrvHolds Then
        SrvHolds = False
        SyncUnlock REGS_LOCK
    EndIf
    NetErrors = NetErrors + 1
    If NetErrors > 65535 Then NetErrors = 0
    Wait 0.01
Fend

' what a PC write starts: the transfer request (xfer_seq changed) at once, and the command block
' handed to main when the write covered cmd_seq (the block is written in one request). While
' main does not run, the command is acknowledged and refused here.
Function AfterWrite(ofs As Long, cnt As Long)
    Long i
    If ofs <= R_XFER_SEQ And R_XFER_SEQ < ofs + cnt Then
        If Regs(R_XFER_SEQ) <> LastXfer Then
            LastXfer = Regs(R_XFER_SEQ)
            ServeTransfer()
        EndIf
    EndIf
    If ofs <= R_CMD_SEQ And R_CMD_SEQ < ofs + cnt Then
        For i = 0 To R_CMD_TOKEN + 1 - R_CMD_CODE
            CmdSnap(i) = Regs(R_CMD_CODE + i)
        Next
        If MainUp Then
            CmdWritten = True
        Else
            RefuseWhileDown()
        EndIf
    EndIf
Fend

' main (the motion side) does not run: acknowledge, keep the sequence rule, refuse NOT_READY
Function RefuseWhileDown
    Long seq, expected
    seq = CmdSnap(R_CMD_SEQ - R_CMD_CODE)
    If seq = LastSeq Then Exit Function
    expected = (LastSeq Mod 65535) + 1
    LastSeq = seq
    Regs(R_ACK_SEQ) = seq
    If seq <> expected Then
        Refuse(seq, E_SEQUENCE_ERROR, 0, 0)
    Else
        Refuse(seq, E_NOT_READY, 0, 0)
    EndIf
Fend
