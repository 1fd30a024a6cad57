import { z } from 'zod/mini';
import { preprocess } from '../../fleet/schema';

/**
 * Wire formats of DuetSoftwareFramework (SBC mode), as `../shared/protocols/duet-dsf-rest-api.txt`
 * and the fixtures in `tests/fixtures/duet/` show them. Every schema is lenient: the object model
 * grows every release (unknown keys pass through), enums gain values (unknown values map to
 * "unknown (raw …)"), numbers sometimes arrive as strings, arrays have `null` holes.
 *
 * Known mistakes of the official OpenAPI file (`dsf/OpenAPI.yaml`, 3.5.0), where we follow the
 * wiki document and real DSF instead: it declares `/machine/code` as GET (it is POST with a
 * plain-text body), it says nothing of 401, and it describes the connect answer as always
 * having `sessionKey` (we accept it missing: no password protection).
 */

// ---------------------------------------------------------------- helpers

/** A number, also when sent as a numeric string. */
export const num = preprocess(
  (v) => (typeof v === 'string' && v.trim() !== '' && !Number.isNaN(Number(v)) ? Number(v) : v),
  z.number(),
);
export const numOrNull = z.pipe(
  z.optional(z.nullable(num)),
  z.transform((v) => v ?? null),
);
export const strOrNull = z.pipe(
  z.optional(z.nullable(z.string())),
  z.transform((v) => v ?? null),
);

/** An enum whose unknown values survive as "unknown (raw …)". */
export function lenientEnum<const T extends readonly string[]>(values: T) {
  return z.pipe(
    z.union([z.string(), z.number()]),
    z.transform((v): T[number] | `unknown (raw ${string})` => {
      const s = String(v);
      return (values as readonly string[]).includes(s) ? (s as T[number]) : `unknown (raw ${s})`;
    }),
  );
}

/** An array whose items may be `null` holes (heaters, tools, fans, endstops). */
function holey<T extends z.ZodMiniType>(item: T) {
  return z._default(z.array(z.nullable(item)), []);
}

// ---------------------------------------------------------------- session

/**
 * `GET /machine/connect` → `{ sessionKey, … }`. `sessionKey` is optional: the gateway holds the DSF
 * session and answers without it (the other fields pass); it is also missing from DSF without
 * password protection. Only a simulator answering in the page (msw, in tests) gives one.
 */
export const connectResponse = z.looseObject({ sessionKey: strOrNull });
export type ConnectResponse = z.infer<typeof connectResponse>;

// ---------------------------------------------------------------- object model

/** `state.status`: the 14 values of DSF 3.5 (MachineStatus). */
export const MACHINE_STATUSES = [
  'disconnected',
  'starting',
  'updating',
  'off',
  'halted',
  'pausing',
  'paused',
  'resuming',
  'cancelling',
  'processing',
  'simulating',
  'busy',
  'changingTool',
  'idle',
] as const;
export const machineStatus = lenientEnum(MACHINE_STATUSES);
export type MachineStatus = z.infer<typeof machineStatus>;

export const HEATER_STATES = ['off', 'standby', 'active', 'fault', 'tuning', 'offline'] as const;
export const heaterState = lenientEnum(HEATER_STATES);

export const MACHINE_MODES = ['FFF', 'CNC', 'Laser'] as const;

/**
 * `state.messageBox` (M291). `mode` is a number 0–7: 0 no buttons, 1 close only (non-blocking),
 * 2 OK, 3 OK/cancel, 4 choices, 5 integer, 6 float, 7 string. `axisControls` is a bitmap of
 * axes to show jog controls for. `default`, `min`, `max`, `choices` depend on the mode.
 */
export const messageBoxSchema = z.looseObject({
  axisControls: z._default(z.optional(num), 0),
  cancelButton: z._default(z.optional(z.boolean()), false),
  choices: z._default(z.optional(z.nullable(z.array(z.string()))), null),
  default: z._default(z.optional(z.nullable(z.union([z.number(), z.string()]))), null),
  max: numOrNull,
  message: z._default(z.optional(z.string()), ''),
  min: numOrNull,
  mode: num,
  seq: num,
  timeout: z._default(z.optional(num), 0),
  title: z._default(z.optional(z.string()), ''),
});
export type MessageBox = z.infer<typeof messageBoxSchema>;

const minMaxCurrent = z._default(
  z.optional(z.nullable(z.looseObject({ current: numOrNull, min: numOrNull, max: numOrNull }))),
  null,
);

export const boardSchema = z.looseObject({
  firmwareName: strOrNull,
  firmwareVersion: strOrNull,
  firmwareDate: strOrNull,
  name: strOrNull,
  shortName: strOrNull,
  mcuTemp: minMaxCurrent,
  vIn: minMaxCurrent,
  v12: minMaxCurrent,
});

export const heaterSchema = z.looseObject({
  active: z._default(z.optional(num), 0),
  standby: z._default(z.optional(num), 0),
  current: z._default(z.optional(num), -273.15),
  state: z._default(z.optional(heaterState), 'off'),
  max: numOrNull,
  min: numOrNull,
  sensor: z._default(z.optional(num), -1),
});
export type Heater = z.infer<typeof heaterSchema>;

export const axisSchema = z.looseObject({
  letter: z.string(),
  homed: z._default(z.optional(z.boolean()), false),
  visible: z._default(z.optional(z.boolean()), true),
  userPosition: numOrNull,
  machinePosition: numOrNull,
  min: numOrNull,
  max: numOrNull,
});

export const extruderSchema = z.looseObject({
  position: numOrNull,
  filament: z._default(z.optional(z.string()), ''),
  factor: numOrNull,
});

export const fanSchema = z.looseObject({
  name: z._default(z.optional(z.string()), ''),
  actualValue: numOrNull,
  requestedValue: numOrNull,
  rpm: numOrNull,
});

export const toolSchema = z.looseObject({
  number: num,
  name: z._default(z.optional(z.string()), ''),
  heaters: z._default(z.optional(z.array(num)), []),
  active: z._default(z.optional(z.array(num)), []),
  standby: z._default(z.optional(z.array(num)), []),
  extruders: z._default(z.optional(z.array(num)), []),
  fans: z._default(z.optional(z.array(num)), []),
  state: z._default(z.optional(lenientEnum(['off', 'active', 'standby'] as const)), 'off'),
});

export const volumeSchema = z.looseObject({
  path: strOrNull,
  name: strOrNull,
  mounted: z._default(z.optional(z.boolean()), false),
  freeSpace: numOrNull,
  capacity: numOrNull,
});

export const thumbnailSchema = z.looseObject({
  format: lenientEnum(['png', 'jpeg', 'qoi'] as const),
  width: z._default(z.optional(num), 0),
  height: z._default(z.optional(num), 0),
  offset: numOrNull,
  size: numOrNull,
  /** base64, only when asked for (`readThumbnailContent=true`) or in `job.file`. */
  data: strOrNull,
});
export type Thumbnail = z.infer<typeof thumbnailSchema>;

/** ParsedFileInfo: `job.file` and `GET /machine/fileinfo/…`. When idle `job.file` has empty fields. */
export const parsedFileInfoSchema = z.looseObject({
  fileName: strOrNull,
  size: z._default(z.optional(num), 0),
  lastModified: strOrNull,
  height: z._default(z.optional(num), 0),
  layerHeight: z._default(z.optional(num), 0),
  numLayers: z._default(z.optional(num), 0),
  printTime: numOrNull,
  simulatedTime: numOrNull,
  generatedBy: strOrNull,
  filament: z._default(z.optional(z.array(num)), []),
  thumbnails: z._default(z.optional(z.array(thumbnailSchema)), []),
});
export type ParsedFileInfo = z.infer<typeof parsedFileInfoSchema>;

export const jobSchema = z.looseObject({
  file: z._default(z.optional(z.nullable(parsedFileInfoSchema)), null),
  filePosition: numOrNull,
  duration: numOrNull,
  layer: numOrNull,
  layerTime: numOrNull,
  lastFileName: strOrNull,
  lastFileCancelled: z._default(z.optional(z.boolean()), false),
  lastFileAborted: z._default(z.optional(z.boolean()), false),
  lastFileSimulated: z._default(z.optional(z.boolean()), false),
  lastDuration: numOrNull,
  pauseDuration: numOrNull,
  warmUpDuration: numOrNull,
  timesLeft: z._default(
    z.optional(z.nullable(z.looseObject({ file: numOrNull, filament: numOrNull, slicer: numOrNull }))),
    null,
  ),
});

export const pluginSchema = z.looseObject({
  id: z._default(z.optional(z.string()), ''),
  name: z._default(z.optional(z.string()), ''),
  author: z._default(z.optional(z.string()), ''),
  version: z._default(z.optional(z.string()), ''),
  homepage: strOrNull,
  license: strOrNull,
  /** pid > 0: running on the SBC; -1 not running (or no SBC part). */
  pid: z._default(z.optional(num), -1),
  sbcExecutable: strOrNull,
  sbcRequired: z._default(z.optional(z.boolean()), false),
});
export type Plugin = z.infer<typeof pluginSchema>;

/** `messages[]` entries: `type` 0 info (generic), 1 warning, 2 error. */
export const messageSchema = z.looseObject({
  content: z._default(z.optional(z.string()), ''),
  time: strOrNull,
  type: z._default(z.optional(num), 0),
});
export type DuetMessage = z.infer<typeof messageSchema>;

export function messageLevel(type: number): 'info' | 'warning' | 'error' {
  return type === 2 ? 'error' : type === 1 ? 'warning' : 'info';
}

export const objectModelSchema = z.looseObject({
  boards: holey(boardSchema),
  directories: z.pipe(
    z.optional(
      z.looseObject({
        filaments: z._default(z.optional(z.string()), '0:/filaments'),
        firmware: z._default(z.optional(z.string()), '0:/firmware'),
        gCodes: z._default(z.optional(z.string()), '0:/gcodes'),
        macros: z._default(z.optional(z.string()), '0:/macros'),
        menu: z._default(z.optional(z.string()), '0:/menu'),
        system: z._default(z.optional(z.string()), '0:/sys'),
        web: z._default(z.optional(z.string()), '0:/www'),
      }),
    ),
    z.transform(
      (d) =>
        d ?? {
          filaments: '0:/filaments',
          firmware: '0:/firmware',
          gCodes: '0:/gcodes',
          macros: '0:/macros',
          menu: '0:/menu',
          system: '0:/sys',
          web: '0:/www',
        },
    ),
  ),
  fans: holey(fanSchema),
  heat: z.pipe(
    z.optional(
      z.looseObject({
        heaters: holey(heaterSchema),
        /** -1 = no heater at that index */
        bedHeaters: z._default(z.optional(z.array(num)), []),
        chamberHeaters: z._default(z.optional(z.array(num)), []),
      }),
    ),
    z.transform((h) => h ?? { heaters: [], bedHeaters: [], chamberHeaters: [] }),
  ),
  job: z.pipe(
    z.optional(jobSchema),
    z.transform((j) => j ?? jobSchema.parse({})),
  ),
  move: z.pipe(
    z.optional(
      z.looseObject({
        axes: holey(axisSchema),
        extruders: holey(extruderSchema),
        compensation: z._default(
          z.optional(
            z.nullable(z.looseObject({ file: strOrNull, type: z._default(z.optional(z.string()), 'none') })),
          ),
          null,
        ),
        speedFactor: numOrNull,
        kinematics: z._default(
          z.optional(z.nullable(z.looseObject({ name: z._default(z.optional(z.string()), '') }))),
          null,
        ),
      }),
    ),
    z.transform(
      (m) => m ?? { axes: [], extruders: [], compensation: null, speedFactor: null, kinematics: null },
    ),
  ),
  network: z._default(z.optional(z.nullable(z.looseObject({ name: strOrNull, hostname: strOrNull }))), null),
  plugins: z.pipe(
    z.optional(z.nullable(z.record(z.string(), z.nullable(pluginSchema)))),
    z.transform((p) => {
      const out: Record<string, Plugin> = {};
      for (const [k, v] of Object.entries(p ?? {})) if (v) out[k] = v;
      return out;
    }),
  ),
  sbc: z._default(
    z.optional(
      z.nullable(
        z.looseObject({
          dsf: z._default(z.optional(z.nullable(z.looseObject({ version: strOrNull }))), null),
        }),
      ),
    ),
    null,
  ),
  state: z.looseObject({
    status: machineStatus,
    machineMode: z._default(z.optional(lenientEnum(MACHINE_MODES)), 'FFF'),
    messageBox: z._default(z.optional(z.nullable(messageBoxSchema)), null),
    currentTool: z._default(z.optional(num), -1),
    displayMessage: z._default(z.optional(z.nullable(z.string())), ''),
    upTime: numOrNull,
    time: strOrNull,
  }),
  tools: holey(toolSchema),
  volumes: holey(volumeSchema),
});
export type ObjectModel = z.infer<typeof objectModelSchema>;

// ---------------------------------------------------------------- files

/** `GET /machine/directory/{dir}` items: `type` 'd' or 'f'; `size` only for files. */
export const dirEntrySchema = z.looseObject({
  type: lenientEnum(['d', 'f'] as const),
  name: z.string(),
  size: numOrNull,
  date: strOrNull,
});
export const directoryListing = z.array(dirEntrySchema);
export type DirEntry = z.infer<typeof dirEntrySchema>;

// ---------------------------------------------------------------- height map

export interface HeightMap {
  xmin: number;
  xmax: number;
  ymin: number;
  ymax: number;
  radius: number;
  xspacing: number;
  yspacing: number;
  xnum: number;
  ynum: number;
  /** rows (y) of columns (x); null = not probed (RRF writes 0 for unprobed points in v2 files
   * that have no "probed" flag, so we keep the numbers as they are). */
  points: number[][];
  header: string;
}

/**
 * RRF "height map file v2": a comment line, a header line of names, a line of values, then ynum
 * rows of xnum comma-separated numbers. Throws with a message on anything else.
 */
export function parseHeightMap(text: string): HeightMap {
  const lines = text.split(/\r?\n/).filter((l) => l.trim() !== '');
  if (lines.length < 3) throw new Error('Height map: too few lines');
  const header = lines[0] ?? '';
  if (!/height map/i.test(header)) throw new Error('Height map: not a RepRapFirmware height map file');
  const names = (lines[1] ?? '').split(',').map((s) => s.trim());
  const values = (lines[2] ?? '').split(',').map((s) => Number(s.trim()));
  const field = (n: string): number => {
    const i = names.indexOf(n);
    const v = i >= 0 ? values[i] : undefined;
    if (v === undefined || Number.isNaN(v)) throw new Error(`Height map: missing ${n}`);
    return v;
  };
  const hm = {
    xmin: field('xmin'),
    xmax: field('xmax'),
    ymin: field('ymin'),
    ymax: field('ymax'),
    radius: field('radius'),
    xspacing: field('xspacing'),
    yspacing: field('yspacing'),
    xnum: field('xnum'),
    ynum: field('ynum'),
  };
  const points = lines.slice(3, 3 + hm.ynum).map((l, row) => {
    const p = l.split(',').map((s) => Number(s.trim()));
    if (p.length !== hm.xnum || p.some((n) => Number.isNaN(n)))
      throw new Error(`Height map: bad row ${row + 1}`);
    return p;
  });
  if (points.length !== hm.ynum) throw new Error('Height map: missing rows');
  return { ...hm, points, header };
}
