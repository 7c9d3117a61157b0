MODULE RobocalServer
    !*************************************************************************************
    ! RobocalServer: the controller side of the robocal line protocol, version 1
    ! (drivers/abb/PROTOCOL.md). A TCP server: robocal connects with socket://IP:PORT.
    ! Sockets need Socket Messaging; moves use MoveAbsJ \Conc (see Behaviour).
    !
    ! Controller configuration
    !   - RobotWare 6 (IRC5): option 616-1 PC Interface, which includes Socket Messaging.
    !     OmniCore (RobotWare 7): check that Socket Messaging is part of the installed system.
    !   - No Multitasking option needed: a move is started with MoveAbsJ \Conc, so this
    !     task keeps answering STATUS / JOINTS / STOP while the arm moves.
    !   - SERVER_IP: the controller address robocal reaches. 192.168.125.1 is the IRC5
    !     service port; for the WAN port use the address set under Configuration >
    !     Communication > IP Setting (and allow the port in the firewall manager, if set).
    !   - SERVER_PORT: ports 1025..4999 are free for user sockets.
    !   - LIM_LO / LIM_HI: inside the controller's own axis limits (MOC: Arm > Upper/Lower
    !     Joint Bound), so that this check refuses a target before the motion system would
    !     stop on it. HELLO reports them: robocal refuses to drive a cell whose robot model
    !     allows more, and checks every move against the tighter of the two.
    !   - CONTROLLER_NAME: a label for this cell, [A-Za-z0-9_.-], at most 32 characters.
    !
    ! Loading and running
    !   1. Copy RobocalServer.mod to the controller (e.g. HOME:/robocal/) with RobotStudio
    !      or FTP.
    !   2. FlexPendant: Program Editor > Modules > File > Load Module (or RobotStudio:
    !      RAPID > T_ROB1 > Load Module) into the motion task T_ROB1. Remove any other
    !      module defining main.
    !   3. Set the program pointer to main (Debug > PP to Main), motors on, AUTO mode,
    !      start. The program then waits for robocal to connect.
    !   4. In robocal: ControllerClient("socket://192.168.125.1:1025", robot).
    !
    ! Behaviour
    !   - One client at a time; the newest connection wins. While serving a client the
    !     server polls for a new connection every POLL_S; one that arrives pre-empts the
    !     old client (closed, after the lines it sent were handled in order). A client that
    !     hangs, or vanished without closing, cannot lock out the next one, and a STOP sent
    !     on a new connection (with no HELLO first) is handled within about 2 x POLL_S.
    !     A client silent for IDLE_TIMEOUT_S seconds is dropped as well.
    !   - STOP is never queued behind motion: no handler waits for the arm (MoveAbsJ
    !     \Conc), so a STOP on the open connection is handled as soon as it is read, and
    !     always: also in FAULT, also before HELLO.
    !   - Moves: MoveAbsJ \Conc to the target, total time \T = the expected duration
    !     (largest joint travel / AXIS_SPEED, plus ACCEL_S), zone fine, tool0.
    !   - A client disconnecting during a move does not stop the move.
    !   - FAULT: a motion error reported while this program runs (IError, MOTION_ERR), or
    !     an error raised by MoveAbsJ itself. Cleared only by RESET; HELLO does not clear it.
    !     Errors that stop program execution end the server: the client then sees a
    !     dropped connection, and the operator restarts the program after the fault.
    !   - All strings stay within RAPID's 80 characters: requests and replies are at most
    !     80 characters by the protocol.
    !*************************************************************************************

    LOCAL CONST string CONTROLLER_NAME := "IRB2600-01";
    LOCAL CONST string PROTOCOL_VERSION := "1";
    LOCAL CONST num N_JOINTS := 6;
    LOCAL CONST string SERVER_IP := "192.168.125.1";
    LOCAL CONST num SERVER_PORT := 1025;
    LOCAL CONST num IDLE_TIMEOUT_S := 60;
    ! Receive and accept poll, seconds: how long a STOP on a new connection may wait.
    LOCAL CONST num POLL_S := 0.05;

    ! Joint limits, degrees: ABB IRB 2600 data sheet, as in solver/robot.py IRB2600.
    LOCAL CONST num LIM_LO{6} := [-180, -95, -180, -400, -120, -400];
    LOCAL CONST num LIM_HI{6} := [180, 155, 75, 400, 120, 400];
    ! Joint speeds (deg/s) for the planned duration; lower them to move more gently.
    LOCAL CONST num AXIS_SPEED{6} := [175, 175, 175, 360, 360, 360];
    LOCAL CONST num ACCEL_S := 0.6;
    ! INPOS once the planned time is over and every axis is this close to the target (deg).
    LOCAL CONST num INPOS_TOL := 0.02;
    ! Largest magnitude accepted for a number, so that no reply can exceed 80 characters.
    LOCAL CONST num MAX_ABS_VALUE := 99999;

    LOCAL CONST string LF := "\0A";
    LOCAL CONST string CR := "\0D";

    LOCAL VAR socketdev serverSocket;
    ! Two client sockets: the one served (current = 1: socketA, 2: socketB) and the spare
    ! that accepts a newer client, which then pre-empts it (socketdev cannot be assigned).
    LOCAL VAR socketdev socketA;
    LOCAL VAR socketdev socketB;
    LOCAL VAR num current := 1;
    LOCAL VAR string rxBuf := "";
    LOCAL VAR bool rxOverflow := FALSE;
    LOCAL VAR clock idleClock;
    LOCAL VAR intnum faultIntno;

    ! The state reported by STATUS (see CurrentState)
    LOCAL VAR num lastMoveId := 0;
    LOCAL VAR bool moveActive := FALSE;
    LOCAL VAR bool moveStopped := FALSE;
    LOCAL VAR num faultCode := 0;
    LOCAL VAR jointtarget moveTarget;
    LOCAL VAR num moveDuration := 0;
    LOCAL VAR clock moveClock;
    ! Overridden by \T in every move; kept moderate in case \T is ever removed.
    LOCAL VAR speeddata calSpeed := [500, 100, 5000, 1000];

    PROC main()
        InitServer;
        WHILE TRUE DO
            IF current = 1 THEN
                SocketAccept serverSocket, socketA \Time:=WAIT_MAX;
            ELSE
                SocketAccept serverSocket, socketB \Time:=WAIT_MAX;
            ENDIF
            ServeClient;
        ENDWHILE
    ENDPROC

    LOCAL PROC InitServer()
        ! Closing first lets the program be restarted from main while sockets are open.
        SocketClose socketA;
        SocketClose socketB;
        SocketClose serverSocket;
        SocketCreate serverSocket;
        SocketBind serverSocket, SERVER_IP, SERVER_PORT;
        SocketListen serverSocket;
        IDelete faultIntno;
        CONNECT faultIntno WITH FaultTrap;
        IError MOTION_ERR, TYPE_ERR, faultIntno;
    ENDPROC

    ! Serve the current client until it leaves or idles out; a newer client pre-empts it.
    LOCAL PROC ServeClient()
        VAR string line;

        StartClient;
        WHILE TRUE DO
            IF ReadLine(line) THEN
                ClkReset idleClock;
                ClkStart idleClock;
                IF rxOverflow THEN
                    rxOverflow := FALSE;
                    SendLine 0, "ERR BAD_REQUEST line too long";
                ELSE
                    HandleLine line;
                ENDIF
            ELSEIF NewClient() THEN
                ! The newest connection wins: the old client is hung or gone, and the new
                ! one may carry a STOP that must not wait for it.
                CloseClient;
                current := 3 - current;
                StartClient;
            ELSEIF ClkRead(idleClock) > IDLE_TIMEOUT_S THEN
                CloseClient;
                RETURN;
            ENDIF
        ENDWHILE
    ERROR
        IF ERRNO = ERR_SOCK_CLOSED THEN
            ! The client left: back to main to accept the next one.
            CloseClient;
            RETURN;
        ENDIF
        RAISE;
    ENDPROC

    LOCAL PROC StartClient()
        rxBuf := "";
        rxOverflow := FALSE;
        ClkReset idleClock;
        ClkStart idleClock;
    ENDPROC

    LOCAL PROC CloseClient()
        IF current = 1 THEN
            SocketClose socketA;
        ELSE
            SocketClose socketB;
        ENDIF
    ENDPROC

    ! TRUE if another client connected within POLL_S (accepted into the spare socket).
    LOCAL FUNC bool NewClient()
        IF current = 1 THEN
            SocketAccept serverSocket, socketB \Time:=POLL_S;
        ELSE
            SocketAccept serverSocket, socketA \Time:=POLL_S;
        ENDIF
        RETURN TRUE;
    ERROR
        IF ERRNO = ERR_SOCK_TIMEOUT THEN
            RETURN FALSE;
        ENDIF
        RAISE;
    ENDFUNC

    ! The next line from the client, without LF (and CR), or FALSE if none is complete
    ! within POLL_S (what arrived stays in rxBuf). rxOverflow: the line was longer than a
    ! RAPID string; its end is returned and must be refused.
    LOCAL FUNC bool ReadLine(INOUT string line)
        VAR string chunk;
        VAR num nl;

        nl := FindChar(rxBuf, 1, LF);
        WHILE nl > StrLen(rxBuf) DO
            ! \Str receives what has arrived, at most 80 characters; lines may be split.
            IF current = 1 THEN
                SocketReceive socketA \Str:=chunk \Time:=POLL_S;
            ELSE
                SocketReceive socketB \Str:=chunk \Time:=POLL_S;
            ENDIF
            IF StrLen(rxBuf) + StrLen(chunk) > 80 THEN
                rxOverflow := TRUE;
                rxBuf := chunk;
            ELSE
                rxBuf := rxBuf + chunk;
            ENDIF
            nl := FindChar(rxBuf, 1, LF);
        ENDWHILE
        line := "";
        IF nl > 1 THEN
            line := StrPart(rxBuf, 1, nl - 1);
        ENDIF
        IF nl >= StrLen(rxBuf) THEN
            rxBuf := "";
        ELSE
            rxBuf := StrPart(rxBuf, nl + 1, StrLen(rxBuf) - nl);
        ENDIF
        IF StrLen(line) = 1 AND line = CR THEN
            line := "";
        ELSEIF StrLen(line) > 1 THEN
            IF StrPart(line, StrLen(line), 1) = CR THEN
                line := StrPart(line, 1, StrLen(line) - 1);
            ENDIF
        ENDIF
        RETURN TRUE;
    ERROR
        IF ERRNO = ERR_SOCK_TIMEOUT THEN
            RETURN FALSE;
        ENDIF
        RAISE;
    ENDFUNC

    ! "#<id> <COMMAND> [values]" -> the command's handler; every request gets one reply.
    LOCAL PROC HandleLine(string line)
        VAR num pos := 1;
        VAR num id := 0;
        VAR string tok;
        VAR string cmd;

        NextToken line, pos, tok;
        IF NOT ParseId(tok, id) THEN
            SendLine 0, "ERR BAD_REQUEST expected #<id>";
            RETURN;
        ENDIF
        NextToken line, pos, cmd;
        IF cmd = "MOVEJ" THEN
            DoMoveJ id, line, pos;
            RETURN;
        ENDIF
        NextToken line, pos, tok;
        IF tok <> "" THEN
            SendLine id, "ERR BAD_REQUEST unexpected arguments";
        ELSEIF cmd = "HELLO" THEN
            SendHello id;
        ELSEIF cmd = "STATUS" THEN
            DoStatus id;
        ELSEIF cmd = "JOINTS" THEN
            DoJoints id;
        ELSEIF cmd = "STOP" THEN
            DoStop id;
        ELSEIF cmd = "RESET" THEN
            DoReset id;
        ELSEIF cmd = "" THEN
            SendLine id, "ERR BAD_REQUEST missing command";
        ELSE
            SendLine id, "ERR BAD_REQUEST unknown command";
        ENDIF
    ENDPROC

    LOCAL PROC DoMoveJ(num id, string line, num start)
        VAR num vals{6};
        VAR num n := 0;
        VAR num pos;
        VAR num i;
        VAR string tok;
        VAR jointtarget now;
        VAR num dur;

        pos := start;
        NextToken line, pos, tok;
        WHILE tok <> "" DO
            n := n + 1;
            IF n > N_JOINTS THEN
                SendLine id, "ERR BAD_REQUEST MOVEJ needs " + NumToStr(N_JOINTS, 0) + " values";
                RETURN;
            ENDIF
            IF NOT ParseNumber(tok, vals{n}) THEN
                SendLine id, "ERR BAD_REQUEST bad number for joint " + NumToStr(n, 0);
                RETURN;
            ENDIF
            NextToken line, pos, tok;
        ENDWHILE
        IF n <> N_JOINTS THEN
            SendLine id, "ERR BAD_REQUEST MOVEJ needs " + NumToStr(N_JOINTS, 0) + " values";
            RETURN;
        ENDIF
        IF faultCode <> 0 THEN
            SendLine id, "ERR FAULT " + NumToStr(faultCode, 0);
            RETURN;
        ENDIF
        ! The limit check comes before anything moves: an out-of-limit target never
        ! reaches the motion system.
        FOR i FROM 1 TO N_JOINTS DO
            IF vals{i} < LIM_LO{i} OR vals{i} > LIM_HI{i} THEN
                SendLine id, "ERR LIMIT joint " + NumToStr(i, 0) + " " + NumToStr(vals{i}, 4)
                    + " outside [" + NumToStr(LIM_LO{i}, 4) + ", " + NumToStr(LIM_HI{i}, 4) + "]";
                RETURN;
            ENDIF
        ENDFOR
        IF CurrentState() = "MOVING" THEN
            SendLine id, "ERR BUSY executing move " + NumToStr(lastMoveId, 0);
            RETURN;
        ENDIF

        now := CJointT();
        dur := ACCEL_S;
        FOR i FROM 1 TO N_JOINTS DO
            IF ACCEL_S + Abs(vals{i} - AxisValue(now, i)) / AXIS_SPEED{i} > dur THEN
                dur := ACCEL_S + Abs(vals{i} - AxisValue(now, i)) / AXIS_SPEED{i};
            ENDIF
        ENDFOR
        ! External axes stay where they are.
        moveTarget := now;
        moveTarget.robax.rax_1 := vals{1};
        moveTarget.robax.rax_2 := vals{2};
        moveTarget.robax.rax_3 := vals{3};
        moveTarget.robax.rax_4 := vals{4};
        moveTarget.robax.rax_5 := vals{5};
        moveTarget.robax.rax_6 := vals{6};
        MoveAbsJ \Conc, moveTarget, calSpeed \T:=dur, fine, tool0;
        lastMoveId := id;
        moveActive := TRUE;
        moveStopped := FALSE;
        moveDuration := dur;
        ClkReset moveClock;
        ClkStart moveClock;
        SendLine id, "OK " + NumToStr(dur, 3);
    ERROR
        IF ERRNO = ERR_SOCK_CLOSED OR ERRNO = ERR_SOCK_TIMEOUT THEN
            RAISE;
        ENDIF
        ! MoveAbsJ itself failed: the controller refused the move. Report and keep serving.
        faultCode := ERRNO;
        SendLine id, "ERR FAULT " + NumToStr(faultCode, 0);
        RETURN;
    ENDPROC

    LOCAL PROC DoStatus(num id)
        VAR string state;

        state := CurrentState();
        IF state = "FAULT" THEN
            SendLine id, "OK FAULT " + NumToStr(faultCode, 0) + " " + NumToStr(lastMoveId, 0);
        ELSE
            SendLine id, "OK " + state + " " + NumToStr(lastMoveId, 0);
        ENDIF
    ENDPROC

    LOCAL PROC DoJoints(num id)
        VAR jointtarget now;

        now := CJointT();
        SendLine id, "OK " + NumToStr(now.robax.rax_1, 4) + " " + NumToStr(now.robax.rax_2, 4)
            + " " + NumToStr(now.robax.rax_3, 4) + " " + NumToStr(now.robax.rax_4, 4)
            + " " + NumToStr(now.robax.rax_5, 4) + " " + NumToStr(now.robax.rax_6, 4);
    ENDPROC

    LOCAL PROC DoStop(num id)
        IF CurrentState() = "MOVING" THEN
            moveStopped := TRUE;
            moveActive := FALSE;
        ENDIF
        ! Always halt, whatever the state says: STOP is the one request that must never fail.
        StopMove;
        ClearPath;
        StartMove;
        SendLine id, "OK";
    ENDPROC

    LOCAL PROC DoReset(num id)
        IF faultCode <> 0 THEN
            IF moveActive AND NOT AtTarget() THEN
                moveStopped := TRUE;
            ENDIF
            moveActive := FALSE;
            StopMove;
            ClearPath;
            StartMove;
            faultCode := 0;
        ENDIF
        SendLine id, "OK";
    ENDPROC

    ! IDLE | MOVING | INPOS | STOPPED | FAULT, as PROTOCOL.md defines them.
    LOCAL FUNC string CurrentState()
        IF faultCode <> 0 THEN
            RETURN "FAULT";
        ENDIF
        IF moveActive THEN
            IF ClkRead(moveClock) < moveDuration OR NOT AtTarget() THEN
                RETURN "MOVING";
            ENDIF
        ENDIF
        IF moveStopped THEN
            RETURN "STOPPED";
        ENDIF
        IF lastMoveId = 0 THEN
            RETURN "IDLE";
        ENDIF
        RETURN "INPOS";
    ENDFUNC

    LOCAL FUNC bool AtTarget()
        VAR jointtarget now;
        VAR num i;

        now := CJointT();
        FOR i FROM 1 TO N_JOINTS DO
            IF Abs(AxisValue(now, i) - AxisValue(moveTarget, i)) > INPOS_TOL THEN
                RETURN FALSE;
            ENDIF
        ENDFOR
        RETURN TRUE;
    ENDFUNC

    LOCAL FUNC num AxisValue(jointtarget jt, num axis)
        TEST axis
        CASE 1:
            RETURN jt.robax.rax_1;
        CASE 2:
            RETURN jt.robax.rax_2;
        CASE 3:
            RETURN jt.robax.rax_3;
        CASE 4:
            RETURN jt.robax.rax_4;
        CASE 5:
            RETURN jt.robax.rax_5;
        DEFAULT:
            RETURN jt.robax.rax_6;
        ENDTEST
    ENDFUNC

    ! "#" followed by 1..5 digits.
    LOCAL FUNC bool ParseId(string tok, INOUT num id)
        VAR string digits;

        IF StrLen(tok) < 2 OR StrLen(tok) > 6 THEN
            RETURN FALSE;
        ENDIF
        IF StrPart(tok, 1, 1) <> "#" THEN
            RETURN FALSE;
        ENDIF
        digits := StrPart(tok, 2, StrLen(tok) - 1);
        IF StrFind(digits, 1, STR_DIGIT \NotInSet) <= StrLen(digits) THEN
            RETURN FALSE;
        ENDIF
        RETURN StrToVal(digits, id);
    ENDFUNC

    ! A fixed-point decimal; no exponent, and nothing StrToVal might read as nan or inf.
    LOCAL FUNC bool ParseNumber(string tok, INOUT num value)
        IF StrFind(tok, 1, STR_DIGIT + ".+-" \NotInSet) <= StrLen(tok) THEN
            RETURN FALSE;
        ENDIF
        IF NOT StrToVal(tok, value) THEN
            RETURN FALSE;
        ENDIF
        RETURN Abs(value) <= MAX_ABS_VALUE;
    ENDFUNC

    ! The next space-separated token of s from pos ("" at the end); pos moves past it.
    LOCAL PROC NextToken(string s, INOUT num pos, INOUT string tok)
        VAR num stop;

        tok := "";
        pos := FindChar(s, pos, " " \NotIn);
        IF pos > StrLen(s) THEN
            RETURN;
        ENDIF
        stop := FindChar(s, pos, " ");
        tok := StrPart(s, pos, stop - pos);
        pos := stop;
    ENDPROC

    ! StrFind that also accepts a start past the end (StrFind needs a position inside s).
    LOCAL FUNC num FindChar(string s, num start, string set \switch NotIn)
        IF start > StrLen(s) THEN
            RETURN StrLen(s) + 1;
        ENDIF
        IF Present(NotIn) THEN
            RETURN StrFind(s, start, set \NotInSet);
        ENDIF
        RETURN StrFind(s, start, set);
    ENDFUNC

    ! HELLO's reply carries the limit table: longer than a string, so packed piece by piece.
    LOCAL PROC SendHello(num id)
        VAR rawbytes raw;
        VAR num i;

        ClearRawBytes raw;
        PackRawBytes "#" + NumToStr(id, 0) + " OK " + CONTROLLER_NAME, raw, 1 \ASCII;
        PackRawBytes " " + PROTOCOL_VERSION + " " + NumToStr(N_JOINTS, 0), raw, RawBytesLen(raw) + 1 \ASCII;
        FOR i FROM 1 TO N_JOINTS DO
            PackRawBytes " " + NumToStr(LIM_LO{i}, 4) + " " + NumToStr(LIM_HI{i}, 4), raw, RawBytesLen(raw) + 1 \ASCII;
        ENDFOR
        PackRawBytes LF, raw, RawBytesLen(raw) + 1 \ASCII;
        ClientSend raw;
    ENDPROC

    LOCAL PROC ClientSend(VAR rawbytes raw)
        IF current = 1 THEN
            SocketSend socketA \RawData:=raw;
        ELSE
            SocketSend socketB \RawData:=raw;
        ENDIF
    ENDPROC

    ! "#<id> <body>" + LF in one send, so a reply is never split by us.
    LOCAL PROC SendLine(num id, string body)
        VAR rawbytes raw;

        ClearRawBytes raw;
        ! Id and body packed apart: together they may exceed a RAPID string's 80 characters.
        PackRawBytes "#" + NumToStr(id, 0) + " ", raw, 1 \ASCII;
        PackRawBytes body, raw, RawBytesLen(raw) + 1 \ASCII;
        PackRawBytes LF, raw, RawBytesLen(raw) + 1 \ASCII;
        ClientSend raw;
    ENDPROC

    ! A motion error while we run: FAULT until RESET. Code = domain * 10000 + number,
    ! as in the event log (e.g. 50204, motion supervision).
    LOCAL TRAP FaultTrap
        VAR trapdata errData;
        VAR errdomain domain;
        VAR num number;
        VAR errtype kind;

        GetTrapData errData;
        ReadErrData errData, domain, number, kind;
        faultCode := domain * 10000 + number;
    ENDTRAP
ENDMODULE
