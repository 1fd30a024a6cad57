import {
  addDays,
  daysIn,
  isoDate,
  PROGRAM_NAMES,
  simDay,
  SIM_TOOLS,
  type Day,
  type DayToolTotals,
} from './statsgen';
import { TouchcutSimAuth } from './auth';
import { FEED_MM_S, RAPID_MM_S, TABLE } from './world';

/** What the simulated TouchCut reports: machine info, status, stats, monitor, programs, unloader. */

/** Stats logging range ("weekly, monthly, yearly"): the simulator logs monthly. */
export const SIM_LOG_DAYS = 31;

export abstract class TouchcutSimReports extends TouchcutSimAuth {
  /** TouchCut's current units ("default"). */
  defaultUnits: 'metric' | 'imperial' = 'metric';

  machineInfo(): unknown {
    return {
      programName: 'TouchCut',
      exePath: 'C:\\TouchCut7\\',
      exeName: 'TouchCut7.exe',
      exeVersion: '7.0.123 (simulated)',
      licensedTo: `${this.name} (simulated)`,
      primeCutInfo: 'PrimeCutNE (simulated)',
      registrationInfo: 'Simulated machine',
      contactInfo: {
        companyName: 'Simulated Kinetic service',
        postalAddr: '',
        streetAddr: '',
        countryName: '',
        phone: '',
        fax: '',
        email: '',
        webSite: '',
      },
      tools: [
        { toolType: 'Plasma', toolName: 'Plasma', position: 1 },
        { toolType: 'Marker', toolName: 'Marker', position: 2 },
        { toolType: 'Laser Pointer', toolName: 'Laser Pointer', position: 0 },
      ],
    };
  }

  status(units: 'metric' | 'imperial', user: string | null): Record<string, unknown> {
    const k = units === 'imperial' ? 1 / 25.4 : 1;
    const seg = this.segment;
    const stateName =
      this.mode === 'error'
        ? 'Error'
        : this.mode === 'paused'
          ? 'Paused'
          : this.mode === 'running'
            ? seg?.kind === 'pierce'
              ? 'Piercing'
              : seg?.kind === 'cut'
                ? 'Cutting'
                : 'Rapid Move'
            : this.mode === 'complete'
              ? 'Program Complete'
              : 'Idle';
    const machineState = {
      idle: 'Idle',
      complete: 'Idle',
      running: 'Running',
      paused: 'Paused',
      error: 'Error',
    }[this.mode];
    const programState = {
      idle: 'Idle',
      complete: 'Complete',
      running: 'Running',
      paused: 'Paused',
      error: 'Stopped',
    }[this.mode];
    const moving = this.mode === 'running';
    const feed = moving ? (seg?.kind === 'rapid' ? RAPID_MM_S : seg?.kind === 'cut' ? FEED_MM_S : 0) * 60 : 0;
    const msgs: Array<{ key: string; msg: string }> = [];
    if (this.errorMsg) msgs.push(this.errorMsg);
    if (this.mode === 'paused')
      msgs.push({ key: 'FeedHold', msg: 'Feed hold: press Start on the machine to resume' });
    const v = (x: number) => Math.round(x * k * 1000) / 1000;
    const pose = { vec: [v(this.pos.x), v(this.pos.y), v(this.pos.z)], rot: [0, 0, 0] };
    const lag = moving ? 0.02 : 0;
    return {
      currentUser: user ?? 'Operator',
      isHomed: true,
      machineState,
      programState,
      programOverride: this.feedOverride === 100 ? 'None' : 'Feed Override',
      stateName,
      toolIndex: this.toolOn || moving ? 1 : 0,
      toolName: this.mode === 'idle' ? 'Laser Pointer' : 'Plasma',
      toolOn: this.toolOn,
      spacedCarriages: [1],
      activeCarriages: [1],
      heightControlAuto: true,
      drossBinMode: 'Auto',
      programName: this.mode === 'idle' && this.programCount === 0 ? 'No Active Program' : this.programName,
      programProgress: Math.round(this.progress * 10) / 10,
      plateOrigin: { vec: [v(10), v(12), 0], rot: [0, 0, 0.3] },
      plateRotation: 0.3,
      material: 'MS-10.00 mm (0.394")',
      materialName: 'MS',
      materialThickness: units === 'imperial' ? 0.394 : 10,
      commandedPos: pose,
      actualPos: { vec: [v(this.pos.x - lag), v(this.pos.y + lag), v(this.pos.z)], rot: [0, 0, 0] },
      feedrate: Math.round(feed * k * 10) / 10,
      feedOverride: this.feedOverride,
      msgStatus: msgs,
      units,
    };
  }

  // ---- stats --------------------------------------------------------------------------------

  /** The logging range: [first, endBefore) — "automatically clipped to the available stats logging range". */
  logRange(): { first: string; endBefore: string } {
    const tomorrow = addDays(isoDate(this.now()), 1);
    return { first: addDays(tomorrow, -SIM_LOG_DAYS), endBefore: tomorrow };
  }

  /** Days served for a request, after clipping. */
  clippedDays(start: string | null, endBefore: string | null): string[] {
    const r = this.logRange();
    const valid = (d: string | null) =>
      d && /^\d{4}-\d{2}-\d{2}$/.test(d) && !Number.isNaN(Date.parse(d)) ? d : null;
    const s = valid(start) ?? r.first;
    const e = valid(endBefore) ?? r.endBefore;
    return daysIn(s < r.first ? r.first : s, e > r.endBefore ? r.endBefore : e);
  }

  /** Machine totals: a base from before the logging range, plus every logged day, plus live cutting. */
  machineTotals(): DayToolTotals[] {
    const r = this.logRange();
    const days = daysIn(r.first, r.endBefore).map(simDay);
    return SIM_TOOLS.map(({ tool, name }) => {
      const base =
        tool === 1
          ? { time: 3_600_000, distance: 90_000_000, starts: 120_000, errors: 310 }
          : { time: 0, distance: 0, starts: 0, errors: 0 };
      const sum = { ...base };
      for (const d of days)
        for (const s of d.sessions)
          for (const t of s.toolTotals)
            if (t.tool === tool) {
              sum.time += t.time;
              sum.distance += t.distance;
              sum.starts += t.starts;
              sum.errors += t.errors;
            }
      if (tool === 1) {
        sum.time += this.live.time;
        sum.distance += this.live.distance;
        sum.starts += this.live.starts;
        sum.errors += this.live.errors;
      }
      const round = {
        time: Math.round(sum.time),
        distance: Math.round(sum.distance),
        starts: sum.starts,
        errors: sum.errors,
      };
      return { tool, name, ...round, carriages: [{ carriage: 1, ...round }] };
    });
  }

  stats(query: URLSearchParams, units: 'metric' | 'imperial'): unknown {
    const condensed = ['true', '1'].includes((query.get('condensed') ?? '').toLowerCase());
    const k = units === 'imperial' ? 1 / 25.4 : 1;
    const L = (x: number) => Math.round(x * k * 100) / 100;
    const days: Day[] = this.clippedDays(query.get('start-date'), query.get('end-before-date')).map(simDay);
    const nonZero = (t: { time: number; distance: number; starts: number; errors: number }) =>
      t.time !== 0 || t.distance !== 0 || t.starts !== 0 || t.errors !== 0;
    const tools = (list: DayToolTotals[], lastReset?: string) =>
      list
        .filter((t) => !condensed || nonZero(t))
        .map((t) => ({
          ...t,
          distance: L(t.distance),
          ...(lastReset ? { lastReset } : {}),
          carriages: t.carriages
            .filter((c) => !condensed || nonZero(c))
            .map((c) => ({ ...c, distance: L(c.distance), ...(lastReset ? { lastReset } : {}) })),
        }));
    const machine = this.machineTotals();
    // Resettable totals: reset at the start of the logging range, so they equal the logged days.
    const r = this.logRange();
    const resettable = machine.map((t) => {
      const base =
        t.tool === 1
          ? { time: 3_600_000, distance: 90_000_000, starts: 120_000, errors: 310 }
          : { time: 0, distance: 0, starts: 0, errors: 0 };
      const v = {
        time: t.time - base.time,
        distance: t.distance - base.distance,
        starts: t.starts - base.starts,
        errors: t.errors - base.errors,
      };
      return { ...t, ...v, carriages: [{ carriage: 1, ...v }] };
    });
    return {
      machine: tools(machine),
      machineResettable: tools(resettable, `${r.first}T00:00:00`),
      days: days
        .map((d) => ({
          date: d.date,
          sessions: d.sessions
            .filter((s) => !condensed || s.activeTime > 0)
            .map((s) => ({ ...s, toolTotals: tools(s.toolTotals) })),
          programs: d.programs,
          errors: d.errors,
        }))
        .filter((d) => !condensed || d.sessions.length + d.programs.length + d.errors.length > 0),
      consumables: days
        .flatMap((d) => d.consumables)
        .filter((c) => !condensed || c.pierces + c.distance + c.time > 0)
        .map((c) => ({
          ...c,
          distance: L(c.distance),
          thickness: Math.round(c.thickness * k * 1000) / 1000,
        })),
      units,
    };
  }

  // ---- monitor ------------------------------------------------------------------------------

  monitor(fields: string | null, units: 'metric' | 'imperial'): unknown {
    const k = units === 'imperial' ? 1 / 25.4 : 1;
    const seg = this.segment;
    const moving = this.mode === 'running' && seg?.kind !== 'pierce';
    const dir = seg ? [seg.to[0] - seg.from[0], seg.to[1] - seg.from[1]] : [0, 0];
    const len = Math.hypot(dir[0] ?? 0, dir[1] ?? 0) || 1;
    const speed = moving ? (seg?.kind === 'rapid' ? RAPID_MM_S : FEED_MM_S) * 60 : 0;
    const t = this.now() / 1000;
    const axis = (
      name: string,
      index: number,
      pos: number,
      vel: number,
      max: number,
      torqueLimit: number,
    ) => {
      const err = moving ? 0.01 + 0.01 * Math.sin(t * 3 + index) : 0;
      return {
        name,
        address: `MC, ${name}`,
        index,
        unitType: 'utLength',
        speedUnitType: 'utFeed',
        scale: 1,
        errorCode: this.mode === 'error' && name === 'axisTorch' ? 4 : 0,
        commandedPos: Math.round(pos * k * 1000) / 1000,
        actualPos: Math.round((pos - err) * k * 1000) / 1000,
        posError: Math.round(err * k * 10000) / 10000,
        errorLimit: Math.round(1 * k * 1000) / 1000,
        actualVel: Math.round(Math.abs(vel) * k * 10) / 10,
        torque:
          Math.round(
            (moving && Math.abs(vel) > 0.001
              ? 35 + 20 * Math.abs(Math.sin(t + index))
              : 4 + Math.abs(Math.sin(t + index))) * 10,
          ) / 10,
        torqueLimit,
        isEnabled: true,
        isMoving: moving && Math.abs(vel) > 0.001,
        isPosErrorInputOn: false,
        isHomeInputOn: pos <= 0.5,
        isRevLimInputOn: false,
        isFwdLimInputOn: false,
        isRevSoftLimOn: pos <= 0,
        isFwdSoftLimOn: pos >= max,
        canMoveFwd: pos < max,
        canMoveRev: pos > 0,
        io: [],
      };
    };
    const axes = [
      axis('axisLong', 1, this.pos.x, (speed * (dir[0] ?? 0)) / len, TABLE.w, 150),
      axis('axisShort', 10, this.pos.y, (speed * (dir[1] ?? 0)) / len, TABLE.h, 180),
      axis('axisTorch', 20, this.pos.z, 0, 150, 120),
    ];
    const cutting = this.mode === 'running' && seg?.kind === 'cut';
    const io = {
      din: [
        { name: 'E-Stop OK', address: 'IO, 1', value: true },
        { name: 'Torch Collision', address: 'IO, 2', value: this.errorMsg?.key === 'TorchCollision' },
        { name: 'Arc OK', address: 'IO, 3', value: cutting },
        { name: 'Gas Pressure OK', address: 'IO, 4', value: true },
      ],
      dout: [
        { name: 'Plasma Start', address: 'IO, 17', value: this.toolOn },
        { name: 'Dross Bin Fan', address: 'IO, 18', value: this.mode === 'running' },
        { name: 'Marker Down', address: 'IO, 19', value: false },
      ],
      ain: [
        {
          name: 'Arc Voltage',
          address: 'AI, 1',
          scale: 50,
          value: cutting ? Math.round((128 + 2 * Math.sin(t * 5)) * 10) / 10 : 0,
          unitType: 'V',
        },
        {
          name: 'Gas Pressure',
          address: 'AI, 2',
          scale: 1,
          value: Math.round((6.2 + 0.1 * Math.sin(t)) * 100) / 100,
          unitType: 'bar',
        },
      ],
      aout: [{ name: 'THC Setpoint', address: 'AO, 1', scale: 50, value: cutting ? 128 : 0, unitType: 'V' }],
    };
    // `fields`: comma separated, `*` wildcard under a group ("axes.*", "io.din", "axes.axisLong").
    const want = (fields ?? '')
      .split(',')
      .map((f) => f.trim())
      .filter(Boolean);
    if (want.length === 0) return { io, axes, units };
    const pick = (group: string, name: string) =>
      want.some(
        (f) =>
          f === group ||
          f === `${group}.*` ||
          f === '*' ||
          f.toLowerCase() === `${group}.${name}`.toLowerCase(),
      );
    const ioOut: Record<string, unknown> = {};
    for (const [g, items] of Object.entries(io)) if (pick('io', g)) ioOut[g] = items;
    return {
      // The manual's example answers `"io": []` when no I/O was asked for.
      io: Object.keys(ioOut).length > 0 ? ioOut : [],
      axes: axes.filter((a) => pick('axes', a.name)),
      units,
    };
  }

  // ---- programs, unloader (shapes invented: "interface subject to change") -------------------

  programs(query: URLSearchParams, units: string): unknown {
    const all = PROGRAM_NAMES.map((n, i) => ({
      fileId: 1000 + i,
      name: `${n}.nc`,
      path: `C:\\Jobs\\${n}.nc`,
      parts: 6,
      status: `${n}.nc` === this.programName && this.mode !== 'idle' ? this.mode : 'loaded',
      progress: `${n}.nc` === this.programName ? Math.round(this.progress) : 0,
      modified: `${isoDate(this.now() - i * 86_400_000)}T07:${String(10 + i).padStart(2, '0')}:00`,
    }));
    const offset = Math.max(0, Number(query.get('offset') ?? 0) || 0);
    const limit = Math.max(1, Math.min(100, Number(query.get('limit') ?? 50) || 50));
    const onlyChanged = ['true', '1'].includes((query.get('onlyChangedData') ?? '').toLowerCase());
    const active = {
      fileId: all.find((p) => p.name === this.programName)?.fileId ?? null,
      name: this.programName,
      progress: Math.round(this.progress * 10) / 10,
    };
    if (onlyChanged) return { activeProgram: active, units };
    return {
      total: all.length,
      offset,
      limit,
      programs: all.slice(offset, offset + limit),
      activeProgram: active,
      units,
    };
  }

  unloader(query: URLSearchParams, units: string): unknown {
    const stations = [1, 2].map((s) => ({
      station: s,
      name: s === 1 ? 'Pallet A' : 'Pallet B',
      state: this.mode === 'running' && this.unloaded.at(-1)?.station === s ? 'Unloading' : 'Ready',
      parts: this.unloaded.filter((u) => u.station === s).length,
      capacity: 60,
    }));
    const out: Record<string, unknown> = { stations, units };
    if (['true', '1'].includes((query.get('history') ?? '').toLowerCase())) {
      const start = query.get('start-date');
      const end = query.get('end-before-date');
      out.history = this.unloaded
        .map((u) => ({
          time: new Date(u.time).toISOString(),
          program: u.program,
          part: u.part,
          station: u.station,
        }))
        .filter((u) => (!start || u.time.slice(0, 10) >= start) && (!end || u.time.slice(0, 10) < end));
    }
    return out;
  }
}
