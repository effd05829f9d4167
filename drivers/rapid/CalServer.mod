MODULE CalServer
    !*****************************************************************
    ! CalServer: measurement server for laser-tracker accuracy campaigns.
    !
    ! The PC (drivers/abb_rws.py) commands one fine-point move at a time
    ! through the PERS variables below, over Robot Web Services:
    !   1. it writes cal_kind, cal_target (or cal_ptarget), cal_speed,
    !      cal_settle_s, cal_vmax, cal_override and cal_tool, then writes
    !      cal_req_seq LAST (the trigger);
    !   2. this loop copies the request number to cal_ack_seq, clamps the
    !      speed to cal_vmax (VelSet + clamp), moves with a 'fine' stop
    !      point, waits for standstill plus cal_settle_s, stores the
    !      reached joints in cal_reached and sets cal_done_seq;
    !   3. a recoverable error instead sets cal_err_no, cal_err_msg, writes
    !      a warning to the event log and sets cal_err_seq.
    ! cal_state mirrors [ack, done, err] so the PC polls one symbol.
    ! Errors that stop execution (reach/limit errors, collisions, guard or
    ! emergency stop, motors off) are seen by the PC through the RAPID
    ! execution state, the controller state and the event log.
    !
    ! cal_kind: 0 ping (no motion), 1 MoveAbsJ cal_target,
    !           2 MoveL cal_ptarget (cal_tool, wobj0).
    ! Units: joints deg, positions mm, quaternion w-first, time s, mass kg.
    !
    ! This module has NO main routine: it links next to the production
    ! program. Entry point: PROC cal_run. Either the PC sets the program
    ! pointer to cal_run through RWS ("PP to routine") and puts it back
    ! to main afterwards, or the production main calls it in one line:
    !     cal_run;
    !*****************************************************************

    ! Interface version checked by the PC driver.
    PERS num cal_version:=2;
    ! Request counter written by the PC after all arguments.
    PERS num cal_req_seq:=0;
    ! Request number taken by this loop.
    PERS num cal_ack_seq:=0;
    ! Request number completed (in position and settled).
    PERS num cal_done_seq:=0;
    ! Request number rejected by a recoverable error.
    PERS num cal_err_seq:=0;
    ! ERRNO of the rejection (-1: not a RAPID error).
    PERS num cal_err_no:=0;
    ! Reason of the rejection (max 80 characters).
    PERS string cal_err_msg:="";
    ! Kind of request: 0 ping, 1 MoveAbsJ, 2 MoveL.
    PERS num cal_kind:=0;
    ! Joint target (deg; external axes 9E9 when unused).
    PERS jointtarget cal_target:=[[0,0,0,0,30,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    ! Cartesian target (mm, quaternion w-first) for MoveL.
    PERS robtarget cal_ptarget:=[[600,0,800],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    ! Speed: v_tcp mm/s, v_ori deg/s, v_leax mm/s, v_reax deg/s.
    PERS speeddata cal_speed:=[200,100,5000,1000];
    ! Dwell after standstill before reporting done (s).
    PERS num cal_settle_s:=0.5;
    ! Joints read after settling (deg).
    PERS jointtarget cal_reached:=[[0,0,0,0,30,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    ! Handshake state in one symbol: [ack, done, err] request numbers.
    PERS num cal_state{3}:=[0,0,0];
    ! TCP speed cap (mm/s): VelSet maximum and clamp of cal_speed.
    PERS num cal_vmax:=250;
    ! Speed override (percent of the programmed speed) for VelSet.
    PERS num cal_override:=100;
    ! tool0's frame carrying the payload (kg, centre of gravity mm in the
    ! flange frame); the PC writes the load data.
    PERS tooldata cal_tool:=[TRUE,[[0,0,0],[1,0,0,0]],[0.001,[0,0,0.001],[1,0,0,0],0,0,0]];
    ! Written by the PC with the arguments above; 0 again after a reload
    ! of this module (the PC then writes every argument anew).
    PERS num cal_epoch:=0;

    VAR num cal_seq:=0;
    VAR jointtarget cal_check;
    VAR speeddata cal_v;

    PROC cal_run()
        ! Resynchronise on entry: never replay an old request.
        cal_ack_seq:=cal_req_seq;
        cal_done_seq:=cal_req_seq;
        cal_publish;
        WHILE TRUE DO
            WaitUntil cal_req_seq<>cal_ack_seq\PollRate:=0.05;
            cal_seq:=cal_req_seq;
            cal_ack_seq:=cal_seq;
            cal_publish;
            cal_serve cal_seq;
            cal_publish;
        ENDWHILE
    ENDPROC

    PROC cal_publish()
        cal_state{1}:=cal_ack_seq;
        cal_state{2}:=cal_done_seq;
        cal_state{3}:=cal_err_seq;
    ENDPROC

    PROC cal_limit()
        ! Speed cap: clamp the programmed speed and set VelSet.
        IF cal_vmax<=0 cal_vmax:=1;
        IF cal_override<1 cal_override:=1;
        IF cal_override>100 cal_override:=100;
        cal_v:=cal_speed;
        IF cal_v.v_tcp>cal_vmax cal_v.v_tcp:=cal_vmax;
        IF cal_v.v_leax>cal_vmax cal_v.v_leax:=cal_vmax;
        VelSet cal_override,cal_vmax;
    ENDPROC

    PROC cal_serve(num seq)
        TEST cal_kind
        CASE 0:
            ! Ping: prove the loop is alive, no motion.
        CASE 1:
            cal_limit;
            MoveAbsJ cal_target,cal_v,fine,cal_tool\WObj:=wobj0;
        CASE 2:
            ! Raises a recoverable error if the target is out of reach.
            cal_check:=CalcJointT(cal_ptarget,cal_tool\WObj:=wobj0);
            cal_limit;
            MoveL cal_ptarget,cal_v,fine,cal_tool\WObj:=wobj0;
        DEFAULT:
            cal_reject seq,-1,"CalServer: unknown request kind "+NumToStr(cal_kind,0);
            RETURN;
        ENDTEST
        IF cal_kind<>0 THEN
            WaitTime\InPos,cal_settle_s;
        ENDIF
        cal_reached:=CJointT();
        cal_done_seq:=seq;
    ERROR
        cal_reject seq,ERRNO,"CalServer: move rejected, ERRNO "+NumToStr(ERRNO,0);
        RETURN;
    ENDPROC

    PROC cal_reject(num seq,num err_code,string reason)
        cal_err_no:=err_code;
        cal_err_msg:=reason;
        ErrWrite\W,"CalServer request rejected",reason;
        cal_err_seq:=seq;
    ENDPROC
ENDMODULE
