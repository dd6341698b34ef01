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
'   * This program has NOT run on a real controller, nor in the RC+ simulator. It was not
'     compiled. Build it in RC+ first and fix what the compiler says.
'   * One Modbus client at a time (the station); a second connection waits.
'   * The controller's own kinematics and any arm calibration set with ArmSet are the "nominal"
'     kinematics here: CORRECTION_STATE defaults to 2 (unknown).
'
' INSTALL AND CONFIGURE
'   1. Add this file to an Epson RC+ project and build. Enable background tasks in the
'      controller preferences so that BgMain starts when the project loads [UG-BG]; start main
'      (Auto mode or the Run window) for the motion side.
'   2. Controller TCP/IP port #201 (NET_PORT): server, local port 502 (or the port of
'      [devices] controller), no terminator.
'   3. Set the #defines below: BASE (= [devices] controller_register_base), WORD_ORDER_BIG
'      (1 = "big", 0 = "little"), WATCHDOG_MS, TOOL_NO (a Tool defined as the probe head K),
'      CORRECTION_STATE, MAIN_TASK (main's task number, 1 when started normally), and the soft
'      limits in InitConfig (station units: rad, rad, mm, rad).
'   4. The station's robot file must describe the robot as Epson does: J1, J2, J4 in Epson's
'      zero and sign (deg in SPEL+, rad on the wire), J3 in mm, base frame = Epson's robot
'      coordinates, the elbow flag +1 = J2 > 0.
'   5. With the robot parked at [conformance].park_joints run `station conformance CONFIG`
'      before the first calibration.
'
' WHAT WAS CHECKED (document, page; sources are listed under SOURCES at the end of this header)
'   * Function main ... Fend, Xqt funcName, Do ... Loop, Wait <seconds> (fractions), ' comments,
'     On / Off: the example of [REF-HALT]. Task numbers (normal 1-32, background 65-80):
'     [REF-HALT], [REF-TASKINFO].
'   * If ... Then / Else / EndIf, TaskInfo(task, 3) = -1 when a task does not execute:
'     [REF-TASKINFO] (used to see that main no longer runs).
'   * Go ... Till MemSw(bit) = On, TillOn: [REF-TILL] (MemSw is one of the functions a Till
'     condition may use; TillOn tells whether the condition stopped the motion).
'   * JA(j1, j2, j3, j4) in deg / mm, Go JA(...), point assignment P10 = JA(...): [REF-JA].
'   * Global <type> name(dims): [REF-GLOBAL]; at most 100,000 elements per global array and 3
'     dimensions [REF-GLOBAL], [UG-ARRAYS]: TBuf 3 x 32,000 = 96,000, StoreReg 1,104 x 58 =
'     64,032; local arrays stay under 2,000 elements [UG-ARRAYS].
'   * Types Boolean, Byte (-128..127), Integer (16 bit), Long (32 bit), Double: [UG-TYPES].
'   * Background tasks: BgMain is task 65, starts when the project loads, Xqt from it makes
'     background tasks, not stopped by emergency stop or safeguard, no manipulator commands:
'     [UG-BG]. Program lines are at most 512 characters: [UG-RULES].
'   * OpenNet #p As Server, WaitNet #p, ChkNet(p) (no #; returns the byte count, or -1 open
'     but not connected, -2 used by another task, -3 not open), CloseNet #p, ReadBin # / WriteBin #
'     (receive / send one or more bytes), ports 201-216: [TCP-14.3] - a third-party reprint of
'     Epson's chapter, not Epson's own page (see NOT CONFIRMED).
'   * Speed and Accel are whole percents 1..100: the station's cmd_speed (1..1000, 0.1 %) is
'     rounded and clamped to 1..100 before use; [RCREF80] Command 1 gives PTP acceleration as a
'     whole percent >= 1 (the Accel statement's own page was not found).
'   * The logic was traced against simulators/controller_server.py, controller_tables.py,
'     controller_claim.py (the claim rules) and drivers/correction_table.py; tests/test_robot_programs.py checks every map constant and
'     the CRC polynomial halves against drivers/controller_map.py and zlib.
'
' REPLACED (the constructs issue 28 doubted)
'   * ErrAxis (no page found): a drive fault now reports error_joint 0 ("0 if none", map).
'   * Case 3, 4 (comma list, no Select page found): Select ... Send is no longer used at all;
'     every dispatch is If / ElseIf.
'   * ChkNet(NET_PORT): kept - [TCP-14.3] shows ChkNet(201) without #; NET_PORT is a #define.
'   * User function Exception: renamed MbException.
'   * ~160,000 Long elements: kept, each global array is under the documented 100,000-element
'     limit per array; the total controller memory for globals is NOT CONFIRMED.
'   * Till MemSw(...): kept, confirmed by [REF-TILL].
'   * Accel below 1 %: cannot happen (clamped to 1..100, see above).
'   * NoEmgAbort tasks during an e-stop: replaced by background tasks [UG-BG].
'   * Also removed: TmReset / Tmr (the watchdog counts 0.1 s heartbeat cycles), Mod in the
'     heartbeat, ByRef array parameters (a global Dq() instead), several statements on one
'     line ("a = 1: b = 2"), the ReadOnly() array (a range test, so that zeroed globals are safe).
'   * Fixed: after EResume Next, MoveTask overwrote the error result with 1 or 2 and NominalIK
'     could accept a stale P900; both now flag the error and test the flag.
'
' NOT CONFIRMED (no Epson page for them was found in the stores searched; confirm each in the
'   SPEL+ Language Reference of your RC+ version before the first run)
'   * ReadBin / WriteBin argument form "#port, ByteArray(), count", Epson's Byte arrays for it,
'     and ChkNet / WaitNet / OpenNet / CloseNet beyond the reprint [TCP-14.3]. Public SPEL+ code
'     uses the same form (e.g. WriteBin #204, modMessage(), 8), which is not a confirmation.
'   * Function ... (x As T) As T, return by assigning the function name, Exit Function, Exit
'     Do / Exit For, For ... Next [Step], Do While, ElseIf, single-line If, #define in a .prg.
'   * Operators And / Or / Xor / Not on integers, Mod, Int, Abs, LShift, RShift, &H literals.
'   * MemOn / MemOff, OnErr GoTo label / EResume Next (MoveTask, NominalIK), EStopOn (main's
'     command loop), Agl, PAgl, XY(...) /L /R, P900 = ..., CX / CY / CZ / CU, Here, Tool, Speed,
'     Accel, DegToRad, RadToDeg, True / False; that a background task may call TaskInfo.
'   * Whether a normal task survives an emergency stop (if main is aborted, the background side
'     reports the running motion as E_ESTOP and refuses new commands with E_NOT_READY until
'     main runs again); whether the controller has memory for all globals together; whether
'     starting main really clears the Globals that BgMain uses (see [REF-GLOBAL]).
'   * No SPEL+ executor was added to the tests: the pages found do not define ReadBin, Xqt,
'     OnErr or the expression rules well enough to build one that would prove anything.
'
' SOURCES (download.epson.biz/robots/ww/data/html/... is Epson's online manual set)
'   [REF-HALT]     SPEL+ Language Reference, "Halt Statement", SPEL/en/030/030-120/030-120-010/
'                  030-120-010-010.html (syntax, task numbers, example program).
'   [REF-TASKINFO] SPEL+ Language Reference, "TaskInfo Function", SPEL/en/030/030-230/
'                  030-230-010/030-230-010-050.html (task types Normal / NoPause / NoEmgAbort,
'                  index 3 = -1 when not executing, If / Else / EndIf example).
'   [REF-TILL]     SPEL+ Language Reference, "Till", SPEL/sc/030/030-230/030-230-010/
'                  030-230-010-170.html (condition functions incl. MemSw; TillOn / Stat).
'   [REF-JA]       SPEL+ Language Reference, "JA Function", SPEL_RC800/ja/030/030-140/
'                  030-140-010/030-140-010-130.html and SPEL/tc/... same path.
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
#define BASE 0
#define WORD_ORDER_BIG 1
#define WATCHDOG_MS 1000
#define N_JOINTS 4
#define NET_PORT 201
#define TOOL_NO 1
#define CORRECTION_STATE 2
#define STOP_BIT 0
' the task number of main (the motion side), for TaskInfo [REF-TASKINFO]
#define MAIN_TASK 1

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
' Every Global is zero after a start from the Run / Operator window [REF-GLOBAL]; zero is a
' valid state for all of them (no table, no latch, CRC table rebuilt by the heartbeat).
' the window image (offsets 0..127)
Global Long Regs(127)
' the command block as it arrived (offsets 8..25), and that a write covered cmd_seq
Global Long CmdSnap(17)
Global Boolean CmdWritten
' the transfer store: header page and value pages as the PC wrote them (0 = no such page)
Global Long StoreHdr(29)
Global Integer StoreHdrLen
Global Long StoreReg(1103, 57)
Global Integer StoreLen(1103)
' three table buffers (raw i32 values, canonical header page); SlotRef(slot) = buffer + 1,
' 0 = no table in that slot
Global Long TBuf(2, 31999)
Global Long THdr(2, 29)
Global Integer SlotRef(2)
' CRC-32 table in two 16-bit halves, and the running CRC
Global Long CrcTabHi(255), CrcTabLo(255)
Global Long CrcHi, CrcLo
' robot state
Global Double SoftLo(3), SoftHi(3)
Global Long Status
Global Boolean Latched, Moving, InPosition, WdFired, MainUp
Global Long LastSeq, MotionSeq, HbRobot, LastXfer, HbIdle
' the token of the station that holds the controller, as its high and low word (0, 0: free)
Global Long OwnHi, OwnLo
Global Double Tq(3), Dq(3)
' the controller's pose of the tool (x, y, z mm, u deg), kept by main for READ_INFO
Global Double ActPose(3)
Global Integer MoveSpeedPct
' 0 running, 1 arrived, 2 stopped by STOP (Till), 3 error
Global Integer MoveResult
' Modbus frame buffers (bytes as 0..255 in Long; ReadBin / WriteBin use the Byte arrays)
Global Byte RxB(299), TxB(299)
Global Long Rx(299), Tx(299)

' ---------------- the communication side: background tasks [UG-BG] -----------------------
' BgMain starts as task 65 when the controller loads the project; the Modbus server task
' Xqt'd from it is a background task too. Neither executes a manipulator command.
Function BgMain
    CrcInit
    PublishIdent
    LastXfer = Regs(R_XFER_SEQ)
    Xqt ModbusServer
    Heartbeat
Fend

' the identification registers (re-written every heartbeat)
Function PublishIdent
    Regs(R_MAP_VERSION) = MAP_VERSION
    Regs(R_N_JOINTS) = N_JOINTS
    Regs(R_WATCHDOG_MS) = WATCHDOG_MS
    Regs(R_CORRECTION_STATE) = CORRECTION_STATE
    PutI32 R_ORDER_CHECK, ORDER_CHECK_VALUE
Fend

' every 0.1 s, also while moving: hb_robot, identification, the watchdog on hb_pc (counted in
' heartbeat cycles), and whether main (the motion side) still runs [REF-TASKINFO]
Function Heartbeat
    Long hbPcLast
    hbPcLast = Regs(R_HB_PC)
    HbIdle = 0
    Do
        HbRobot = HbRobot + 1
        If HbRobot > 65535 Then HbRobot = 0
        Regs(R_HB_ROBOT) = HbRobot
        If CrcTabLo(1) = 0 Then CrcInit
        PublishIdent
        If Regs(R_HB_PC) <> hbPcLast Then
            hbPcLast = Regs(R_HB_PC)
            HbIdle = 0
        ElseIf HbIdle < 100000 Then
            HbIdle = HbIdle + 1
        EndIf
        If Moving And HbIdle * 100 > WATCHDOG_MS Then WdFired = True
        ServeClaim
        If TaskInfo(MAIN_TASK, 3) = -1 Then
            MainUp = False
        Else
            MainUp = True
        EndIf
        ' main no longer runs (an emergency stop or an abort ended it): the motion it ran is over
        If Moving And Not MainUp And Not Latched Then
            Moving = False
            Refuse MotionSeq, E_ESTOP, 0, 0
        EndIf
        Wait 0.1
    Loop
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
        FreeClaim
    ElseIf held And rqHi = 65535 - OwnHi And rqLo = 65535 - OwnLo Then
        FreeClaim
    ElseIf Not held And HbIdle * 100 <= WATCHDOG_MS Then
        If rqHi <> 0 Or rqLo <> 0 Then
            OwnHi = rqHi
            OwnLo = rqLo
        EndIf
    EndIf
    PutWords R_CLAIM_OWNER, OwnHi, OwnLo
Fend

' freeing clears the request and the holder's host, PID and since: no stale request is granted
' later, no stale holder named
Function FreeClaim
    OwnHi = 0
    OwnLo = 0
    PutWords R_CLAIM_REQUEST, 0, 0
    PutWords R_CLAIM_HOST, 0, 0
    PutWords R_CLAIM_PID, 0, 0
    PutWords R_CLAIM_SINCE, 0, 0
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
Function U32Hi(off As Integer) As Long
    If WORD_ORDER_BIG = 1 Then
        U32Hi = Regs(off)
    Else
        U32Hi = Regs(off + 1)
    EndIf
Fend

Function U32Lo(off As Integer) As Long
    If WORD_ORDER_BIG = 1 Then
        U32Lo = Regs(off + 1)
    Else
        U32Lo = Regs(off)
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

Function PutWords(off As Integer, hi As Long, lo As Long)
    If WORD_ORDER_BIG = 1 Then
        Regs(off) = hi
        Regs(off + 1) = lo
    Else
        Regs(off) = lo
        Regs(off + 1) = hi
    EndIf
Fend

Function PutI32(off As Integer, v As Long)
    PutWords off, HiWord(v), LoWord(v)
Fend

Function PutI16(off As Integer, v As Long)
    If v < 0 Then
        Regs(off) = v + 65536
    Else
        Regs(off) = v
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
' bytes). CrcHi / CrcLo are its high and low 16 bits.
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

Function CrcStart
    CrcHi = &HFFFF
    CrcLo = &HFFFF
Fend

Function CrcByte(b As Long)
    Integer idx
    idx = (CrcLo And &HFF) Xor b
    CrcLo = (RShift(CrcLo, 8) Or LShift(CrcHi And &HFF, 8)) Xor CrcTabLo(idx)
    CrcHi = RShift(CrcHi, 8) Xor CrcTabHi(idx)
Fend

' one register, high byte first
Function CrcWord(w As Long)
    CrcByte RShift(w, 8) And &HFF
    CrcByte w And &HFF
Fend

Function CrcEnd
    CrcHi = CrcHi Xor &HFFFF
    CrcLo = CrcLo Xor &HFFFF
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
    PublishCrc SLOT_STAGED, R_TABLE_STAGED_CRC
    PublishCrc SLOT_ACTIVE, R_TABLE_ACTIVE_CRC
    PublishCrc SLOT_PREVIOUS, R_TABLE_PREVIOUS_CRC
Fend

' the slot's whole-table CRC (its header's, checked at TABLE_STAGE), 0 for an empty slot
Function PublishCrc(slot As Integer, off As Integer)
    Integer b
    b = SlotOf(slot)
    If b < 0 Then
        PutWords off, 0, 0
    ElseIf WORD_ORDER_BIG = 1 Then
        PutWords off, THdr(b, H_TABLE_CRC), THdr(b, H_TABLE_CRC + 1)
    Else
        PutWords off, THdr(b, H_TABLE_CRC + 1), THdr(b, H_TABLE_CRC)
    EndIf
Fend

' details first, the sequence number last; latching codes latch
Function Refuse(seq As Long, code As Integer, joint As Integer, bound As Integer)
    Regs(R_ERROR_CODE) = code
    PutI16 R_ERROR_JOINT, joint
    PutI16 R_ERROR_BOUND, bound
    If code = E_ESTOP Or code = E_DRIVE_FAULT Or code = E_WATCHDOG_TIMEOUT Then
        Latched = True
        If code = E_ESTOP Then Status = Status Or S_ESTOP
        PublishStatus
    EndIf
    Regs(R_ERROR_SEQ) = seq
Fend

Function ReportDone(seq As Long)
    Regs(R_DONE_SEQ) = seq
Fend

' ---------------- the motion side: main, a normal task ----------------------------------
Function main
    InitConfig
    Tool TOOL_NO
    MoveResult = 1
    Moving = False
    InPosition = True
    CmdWritten = False
    LastSeq = Regs(R_CMD_SEQ)
    WriteActJoints
    PublishStatus
    CommandLoop
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
        PutI32 R_ACT_JOINTS + 2 * j, Counts(v, 1000000)
    Next
    ActPose(0) = CX(Here)
    ActPose(1) = CY(Here)
    ActPose(2) = CZ(Here)
    ActPose(3) = CU(Here)
Fend

' one move, started by Xqt from Dispatch; STOP sets memory bit STOP_BIT, which the Till
' condition watches [REF-TILL]. The error handler only flags: EResume Next continues after Go.
Function MoveTask
    Boolean failed
    failed = False
    OnErr GoTo MoveErr
    Speed MoveSpeedPct
    Accel MoveSpeedPct, MoveSpeedPct
    Go JA(RadToDeg(Tq(0)), RadToDeg(Tq(1)), Tq(2), RadToDeg(Tq(3))) Till MemSw(STOP_BIT) = On
    If failed Then
        MoveResult = 3
    ElseIf TillOn Then
        MoveResult = 2
    Else
        MoveResult = 1
    EndIf
    Exit Function
MoveErr:
    failed = True
    EResume Next
Fend

' stop the running motion and wait until the motion task has ended
Function StopMotion
    MemOn STOP_BIT
    Do While MoveResult = 0 And Not EStopOn
        Wait 0.01
    Loop
    Moving = False
    WriteActJoints
    PublishStatus
Fend

' the command loop: motion results, then a new command block, every 2 ms; act_joints about
' every 0.1 s
Function CommandLoop
    Long seq, expected, code
    Integer tick
    tick = 0
    Do
        If Moving And EStopOn And Not Latched Then
            Moving = False
            WriteActJoints
            Refuse MotionSeq, E_ESTOP, 0, 0
        ElseIf Moving And WdFired Then
            StopMotion
            Refuse MotionSeq, E_WATCHDOG_TIMEOUT, 0, 0
        ElseIf Moving And MoveResult = 1 Then
            Moving = False
            InPosition = True
            WriteActJoints
            PublishStatus
            ReportDone MotionSeq
        ElseIf Moving And MoveResult = 3 Then
            ' the axis is not reported: ErrAxis is not confirmed (error_joint 0 = none, map)
            Moving = False
            WriteActJoints
            Refuse MotionSeq, E_DRIVE_FAULT, 0, 0
        EndIf
        If CmdWritten Then
            CmdWritten = False
            seq = CmdSnap(R_CMD_SEQ - R_CMD_CODE)
            If seq <> LastSeq Then
                expected = LastSeq Mod 65535 + 1
                LastSeq = seq
                code = CmdSnap(0)
                Regs(R_ACK_SEQ) = seq
                If seq <> expected Then
                    Refuse seq, E_SEQUENCE_ERROR, 0, 0
                Else
                    Dispatch seq, code
                EndIf
            EndIf
        EndIf
        tick = tick + 1
        If tick >= 50 Then
            tick = 0
            WriteActJoints
        EndIf
        Wait 0.002
    Loop
Fend

Function SnapI32(off As Integer) As Long
    Integer a
    a = off - R_CMD_CODE
    If WORD_ORDER_BIG = 1 Then
        SnapI32 = JoinI32(CmdSnap(a), CmdSnap(a + 1))
    Else
        SnapI32 = JoinI32(CmdSnap(a + 1), CmdSnap(a))
    EndIf
Fend

' one command (If / ElseIf: no Select ... Send, whose page was not found)
Function Dispatch(seq As Long, code As Long)
    Long elbow, speed
    Integer j, err, bound
    Double pose(5)
    If code = C_STOP Then
        If Moving Then
            StopMotion
            Refuse MotionSeq, E_MOTION_ABORTED, 0, 0
        EndIf
        ReportDone seq
        Exit Function
    EndIf
    ' STOP is obeyed from anyone; every other command only from the holder of the controller
    If Not TokenIsOwner(R_CMD_TOKEN - R_CMD_CODE) Then
        Refuse seq, E_NOT_CLAIMED, 0, 0
        Exit Function
    EndIf
    ' only STOP while a motion runs
    If Moving Then
        Refuse seq, E_BAD_COMMAND, 0, 0
        Exit Function
    EndIf
    elbow = CmdSnap(R_CMD_ELBOW - R_CMD_CODE)
    If elbow >= 32768 Then elbow = elbow - 65536
    speed = CmdSnap(R_CMD_SPEED - R_CMD_CODE)
    If code = C_RESET Then
        Latched = False
        Status = Status And Not S_ESTOP
        Regs(R_ERROR_CODE) = E_NONE
        PutI16 R_ERROR_JOINT, 0
        PutI16 R_ERROR_BOUND, 0
        PublishStatus
        ReportDone seq
    ElseIf code = C_MOVE_JOINTS Or code = C_MOVE_CARTESIAN Then
        If Latched Then
            Refuse seq, E_NOT_READY, 0, 0
            Exit Function
        EndIf
        If speed < 1 Or speed > 1000 Then
            Refuse seq, E_BAD_COMMAND, 0, 0
            Exit Function
        EndIf
        If code = C_MOVE_JOINTS Then
            For j = 0 To N_JOINTS - 1
                Tq(j) = SnapI32(R_CMD_TARGET + 2 * j) * 0.000001
            Next
        Else
            If elbow <> 1 And elbow <> -1 Then
                Refuse seq, E_BAD_COMMAND, 0, 0
                Exit Function
            EndIf
            For j = 0 To 5
                pose(j) = SnapI32(R_CMD_TARGET + 2 * j) * 0.000001
            Next
            If Not NominalIK(pose(0), pose(1), pose(2), pose(5), elbow) Then
                Refuse seq, E_UNREACHABLE, 0, 0
                Exit Function
            EndIf
            If SlotRef(SLOT_ACTIVE) <> 0 Then
                err = Interpolate(SlotOf(SLOT_ACTIVE), pose(0), pose(1), pose(2), pose(5), elbow)
                If err <> E_NONE Then
                    Refuse seq, err, 0, 0
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
                Refuse seq, E_SOFT_LIMIT, j + 1, bound
                Exit Function
            EndIf
        Next
        ' cmd_speed is 0.1 % steps: Speed and Accel take whole percents 1..100
        MoveSpeedPct = Int(speed / 10 + 0.5)
        If MoveSpeedPct < 1 Then MoveSpeedPct = 1
        If MoveSpeedPct > 100 Then MoveSpeedPct = 100
        MoveResult = 0
        WdFired = False
        MotionSeq = seq
        Moving = True
        InPosition = False
        PublishStatus
        MemOff STOP_BIT
        Xqt MoveTask
    ElseIf code = C_TABLE_STAGE Then
        err = StageTable
        PublishStatus
        If err <> E_NONE Then
            Refuse seq, err, 0, 0
        Else
            ReportDone seq
        EndIf
    ElseIf code = C_TABLE_ACTIVATE Or code = C_TABLE_DEACTIVATE Or code = C_TABLE_ROLLBACK Or code = C_TABLE_DISCARD_PREVIOUS Then
        err = SwitchTables(code)
        PublishStatus
        If err <> E_NONE Then
            Refuse seq, err, 0, 0
        Else
            ReportDone seq
        EndIf
    Else
        ' also NONE (0) and unknown codes
        Refuse seq, E_BAD_COMMAND, 0, 0
    EndIf
Fend

' the controller's own inverse kinematics of (x, y, z mm, yaw rad) in the configuration whose J2
' has the sign of elbow; the joints in Tq (station units). False: not reachable. The error
' handler only flags (EResume Next continues after the statement that failed).
Function NominalIK(x As Double, y As Double, z As Double, yaw As Double, elbow As Long) As Boolean
    Integer j, tries
    Double j2
    Boolean failed
    OnErr GoTo IkErr
    NominalIK = False
    For tries = 1 To 2
        failed = False
        If tries = 1 Then
            P900 = XY(x, y, z, RadToDeg(yaw)) /L
        Else
            P900 = XY(x, y, z, RadToDeg(yaw)) /R
        EndIf
        If Not failed Then
            j2 = PAgl(P900, 2)
            If Not failed And ((elbow = 1 And j2 > 0) Or (elbow = -1 And j2 < 0)) Then
                For j = 0 To N_JOINTS - 1
                    Tq(j) = PAgl(P900, j + 1)
                    If j <> 2 Then Tq(j) = DegToRad(Tq(j))
                Next
                If Not failed Then
                    NominalIK = True
                    Exit Function
                EndIf
            EndIf
        EndIf
    Next
    Exit Function
IkErr:
    failed = True
    EResume Next
Fend

' ---------------- the correction table ------------------------------------------------------
Function HdrU32(b As Integer, off As Integer) As Long
    If WORD_ORDER_BIG = 1 Then
        HdrU32 = JoinI32(THdr(b, off), THdr(b, off + 1))
    Else
        HdrU32 = JoinI32(THdr(b, off + 1), THdr(b, off))
    EndIf
Fend

Function StoreI32(off As Integer) As Long
    If WORD_ORDER_BIG = 1 Then
        StoreI32 = JoinI32(StoreHdr(off), StoreHdr(off + 1))
    Else
        StoreI32 = JoinI32(StoreHdr(off + 1), StoreHdr(off))
    EndIf
Fend

' TABLE_STAGE: the stored header checked as CorrectionTableData.decode_header and TableAxis do,
' every value page 0 .. ceil(n/29)-1 stored and n values long together, the whole-table CRC-32
' over the values as big-endian bytes; then the table goes into a free buffer as the staged one
Function StageTable As Integer
    Integer nAxes, i, k, b, nPages, used
    Long nValues, nJoints, nConfigs, prodShape, total, crcHi, crcLo, st, sp, hi, lo, v
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
    CrcStart
    For k = 0 To nPages - 1
        For i = 0 To StoreLen(k) - 1 Step 2
            If WORD_ORDER_BIG = 1 Then
                CrcWord StoreReg(k, i)
                CrcWord StoreReg(k, i + 1)
            Else
                CrcWord StoreReg(k, i + 1)
                CrcWord StoreReg(k, i)
            EndIf
        Next
    Next
    CrcEnd
    If WORD_ORDER_BIG = 1 Then
        crcHi = StoreHdr(H_TABLE_CRC)
        crcLo = StoreHdr(H_TABLE_CRC + 1)
    Else
        crcHi = StoreHdr(H_TABLE_CRC + 1)
        crcLo = StoreHdr(H_TABLE_CRC)
    EndIf
    If CrcHi <> crcHi Or CrcLo <> crcLo Then
        StageTable = E_TABLE_CRC_MISMATCH
        Exit Function
    EndIf
    ' second pass: into the staged slot's buffer, or one no slot uses
    b = SlotOf(SLOT_STAGED)
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
    SlotRef(SLOT_STAGED) = b + 1
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
    Double u, t(3), w, p(3), start, stp
    p(0) = x
    p(1) = y
    p(2) = z
    p(3) = yaw
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
        u = (p(k) - start) / stp
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
Function PageOut(n As Integer)
    Integer i
    CrcStart
    For i = 0 To n - 1
        CrcWord Regs(R_PAGE_DATA + i)
    Next
    CrcEnd
    For i = n To PAGE_DATA_REGISTERS - 1
        Regs(R_PAGE_DATA + i) = 0
    Next
    Regs(R_PAGE_LEN) = n
    PutWords R_PAGE_CRC, CrcHi, CrcLo
Fend

Function ServeTransfer
    Integer op, k, n, i, j, b, slot, nValues, first, count
    Integer err
    Double v
    op = Regs(R_XFER_OP)
    k = Regs(R_PAGE_INDEX)
    n = Regs(R_PAGE_LEN)
    err = E_NONE
    If op = X_WRITE_HEADER Or op = X_WRITE_PAGE Then
        If n > PAGE_DATA_REGISTERS Then
            err = E_PAGE_INVALID
        Else
            CrcStart
            For i = 0 To n - 1
                CrcWord Regs(R_PAGE_DATA + i)
            Next
            CrcEnd
            If CrcHi <> U32Hi(R_PAGE_CRC) Or CrcLo <> U32Lo(R_PAGE_CRC) Then
                err = E_PAGE_CRC_MISMATCH
            ElseIf op = X_WRITE_HEADER Then
                If k <> 0 Or n <> TABLE_HEADER_REGISTERS Then
                    err = E_PAGE_INVALID
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
                err = E_PAGE_INVALID
            Else
                For i = 0 To n - 1
                    StoreReg(k, i) = Regs(R_PAGE_DATA + i)
                Next
                StoreLen(k) = n
            EndIf
        EndIf
    ElseIf op = X_READ_HEADER Then
        If k <> 0 Or StoreHdrLen = 0 Then
            err = E_PAGE_INVALID
        Else
            For i = 0 To StoreHdrLen - 1
                Regs(R_PAGE_DATA + i) = StoreHdr(i)
            Next
            PageOut StoreHdrLen
        EndIf
    ElseIf op = X_READ_PAGE Then
        If k >= MAX_PAGES Then
            err = E_PAGE_INVALID
        ElseIf StoreLen(k) = 0 Then
            err = E_PAGE_INVALID
        Else
            For i = 0 To StoreLen(k) - 1
                Regs(R_PAGE_DATA + i) = StoreReg(k, i)
            Next
            PageOut StoreLen(k)
        EndIf
    ElseIf op = X_READ_INFO And k = INFO_SOFT_LIMITS Then
        For j = 0 To 5
            If j < N_JOINTS Then
                PutI32 R_PAGE_DATA + 4 * j, Counts(SoftLo(j), 1000000)
                PutI32 R_PAGE_DATA + 4 * j + 2, Counts(SoftHi(j), 1000000)
            Else
                PutI32 R_PAGE_DATA + 4 * j, 0
                PutI32 R_PAGE_DATA + 4 * j + 2, 0
            EndIf
        Next
        PageOut 24
    ElseIf op = X_READ_INFO And k = INFO_ACT_POSE Then
        ' the controller's pose of tool TOOL_NO as main last read it (this runs in a background
        ' task, which executes no manipulator command); a SCARA's roll and pitch are 0
        PutI32 R_PAGE_DATA, Counts(ActPose(0), 1000000)
        PutI32 R_PAGE_DATA + 2, Counts(ActPose(1), 1000000)
        PutI32 R_PAGE_DATA + 4, Counts(ActPose(2), 1000000)
        PutI32 R_PAGE_DATA + 6, 0
        PutI32 R_PAGE_DATA + 8, 0
        PutI32 R_PAGE_DATA + 10, Counts(DegToRad(ActPose(3)), 1000000)
        PageOut 12
    ElseIf op >= X_READ_STAGED_HEADER And op <= X_READ_PREVIOUS_PAGE Then
        ' the table in a slot, regenerated as the PC sent it: staged 6/7, active 8/9, previous 10/11
        slot = Int((op - X_READ_STAGED_HEADER) / 2)
        b = SlotOf(slot)
        If b < 0 Then
            err = E_PAGE_INVALID
        ElseIf ((op - X_READ_STAGED_HEADER) Mod 2) = 0 Then
            If k <> 0 Then
                err = E_PAGE_INVALID
            Else
                For i = 0 To TABLE_HEADER_REGISTERS - 1
                    Regs(R_PAGE_DATA + i) = THdr(b, i)
                Next
                PageOut TABLE_HEADER_REGISTERS
            EndIf
        Else
            nValues = HdrU32(b, H_TABLE_N_VALUES)
            first = k * PAGE_VALUES
            If first >= nValues Then
                err = E_PAGE_INVALID
            Else
                count = nValues - first
                If count > PAGE_VALUES Then count = PAGE_VALUES
                For i = 0 To count - 1
                    PutI32 R_PAGE_DATA + 2 * i, TBuf(b, first + i)
                Next
                PageOut 2 * count
            EndIf
        EndIf
    Else
        err = E_PAGE_INVALID
    EndIf
    ' the answer, the number last
    Regs(R_XFER_ERROR) = err
    Regs(R_XFER_ACK) = Regs(R_XFER_SEQ)
Fend


' ---------------- Modbus TCP server (a background task) ---------------------------------
' ChkNet(port) without "#", as in [TCP-14.3]: the bytes waiting, or < 0 when the connection is
' gone (-1 open but not connected, -2 another task uses the port, -3 not open).
Function RecvBytes(n As Integer) As Boolean
    Integer i
    Long v
    RecvBytes = False
    Do While ChkNet(NET_PORT) < n
        If ChkNet(NET_PORT) < 0 Then Exit Function
        Wait 0.001
    Loop
    ReadBin #NET_PORT, RxB(), n
    For i = 0 To n - 1
        ' Byte is -128..127 [UG-TYPES]
        v = RxB(i)
        If v < 0 Then v = v + 256
        Rx(i) = v
    Next
    RecvBytes = True
Fend

Function SendBytes(n As Integer)
    Integer i
    For i = 0 To n - 1
        If Tx(i) > 127 Then
            TxB(i) = Tx(i) - 256
        Else
            TxB(i) = Tx(i)
        EndIf
    Next
    WriteBin #NET_PORT, TxB(), n
Fend

' MBAP header (transaction id, protocol 0, length, unit id) + the PDU already in Tx(7..)
Function Reply(tid As Long, unit As Long, pduLen As Integer)
    Tx(0) = RShift(tid, 8) And &HFF
    Tx(1) = tid And &HFF
    Tx(2) = 0
    Tx(3) = 0
    Tx(4) = RShift(pduLen + 1, 8) And &HFF
    Tx(5) = (pduLen + 1) And &HFF
    Tx(6) = unit
    SendBytes 7 + pduLen
Fend

' a Modbus exception response (function code + 0x80, exception code)
Function MbException(tid As Long, unit As Long, fc As Long, code As Integer)
    Tx(7) = fc Or &H80
    Tx(8) = code
    Reply tid, unit, 2
Fend

' offsets the PC may write: all but hb_robot .. order_check, claim_owner and ack_seq ..
' table_previous_crc
Function PcMayWrite(off As Integer) As Boolean
    PcMayWrite = True
    If off >= R_HB_ROBOT And off <= R_ORDER_CHECK + 1 Then PcMayWrite = False
    If off >= R_CLAIM_OWNER And off <= R_CLAIM_OWNER + 1 Then PcMayWrite = False
    If off >= R_ACK_SEQ And off <= R_TABLE_PREVIOUS_CRC + 1 Then PcMayWrite = False
Fend

Function ModbusServer
    Long tid, unit, fc, addr, cnt, lenField, off, val
    Integer i
    Boolean bad
    Do
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
            off = addr - BASE
            If fc = 3 Or fc = 4 Then
                If cnt < 1 Or cnt > 125 Then
                    MbException tid, unit, fc, 3
                ElseIf off < 0 Or off + cnt > WINDOW_SIZE Then
                    MbException tid, unit, fc, 2
                Else
                    Tx(7) = fc
                    Tx(8) = 2 * cnt
                    For i = 0 To cnt - 1
                        Tx(9 + 2 * i) = RShift(Regs(off + i), 8) And &HFF
                        Tx(10 + 2 * i) = Regs(off + i) And &HFF
                    Next
                    Reply tid, unit, 2 + 2 * cnt
                EndIf
            ElseIf fc = 6 Then
                ' the register's value is in the count field's bytes
                val = cnt
                If off < 0 Or off >= WINDOW_SIZE Then
                    MbException tid, unit, fc, 2
                ElseIf Not PcMayWrite(off) Then
                    MbException tid, unit, fc, 2
                Else
                    Regs(off) = val
                    AfterWrite off, 1
                    For i = 0 To 4
                        Tx(7 + i) = Rx(i)
                    Next
                    Reply tid, unit, 5
                EndIf
            ElseIf fc = 16 Then
                If cnt < 1 Or cnt > 123 Or Rx(5) <> 2 * cnt Then
                    MbException tid, unit, fc, 3
                ElseIf off < 0 Or off + cnt > WINDOW_SIZE Then
                    MbException tid, unit, fc, 2
                Else
                    bad = False
                    For i = 0 To cnt - 1
                        If Not PcMayWrite(off + i) Then bad = True
                    Next
                    If bad Then
                        MbException tid, unit, fc, 2
                    Else
                        For i = 0 To cnt - 1
                            Regs(off + i) = Rx(6 + 2 * i) * 256 + Rx(7 + 2 * i)
                        Next
                        AfterWrite off, cnt
                        For i = 0 To 4
                            Tx(7 + i) = Rx(i)
                        Next
                        Reply tid, unit, 5
                    EndIf
                EndIf
            Else
                MbException tid, unit, fc, 1
            EndIf
        Loop
        CloseNet #NET_PORT
    Loop
Fend

' what a PC write starts: the transfer request (xfer_seq changed) at once, and the command block
' handed to main when the write covered cmd_seq (the block is written in one request). While
' main does not run, the command is acknowledged and refused here.
Function AfterWrite(off As Integer, cnt As Integer)
    Integer i
    If off <= R_XFER_SEQ And R_XFER_SEQ < off + cnt Then
        If Regs(R_XFER_SEQ) <> LastXfer Then
            LastXfer = Regs(R_XFER_SEQ)
            ServeTransfer
        EndIf
    EndIf
    If off <= R_CMD_SEQ And R_CMD_SEQ < off + cnt Then
        For i = 0 To R_CMD_TOKEN + 1 - R_CMD_CODE
            CmdSnap(i) = Regs(R_CMD_CODE + i)
        Next
        If MainUp Then
            CmdWritten = True
        Else
            RefuseWhileDown
        EndIf
    EndIf
Fend

' main (the motion side) does not run: acknowledge, keep the sequence rule, refuse NOT_READY
Function RefuseWhileDown
    Long seq, expected
    seq = CmdSnap(R_CMD_SEQ - R_CMD_CODE)
    If seq = LastSeq Then Exit Function
    expected = LastSeq Mod 65535 + 1
    LastSeq = seq
    Regs(R_ACK_SEQ) = seq
    If seq <> expected Then
        Refuse seq, E_SEQUENCE_ERROR, 0, 0
    Else
        Refuse seq, E_NOT_READY, 0, 0
    EndIf
Fend
