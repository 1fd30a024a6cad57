import { z } from 'zod';

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
export const num = z.preprocess(
  (v) => (typeof v === 'string' && v.trim() !== '' && !Number.isNaN(Number(v)) ? Number(v) : v),
  z.number(),
);
export const numOrNull = num
  .nullable()
  .optional()
  .transform((v) => v ?? null);
export const strOrNull = z
  .string()
  .nullable()
  .optional()
  .transform((v) => v ?? null);

/** An enum whose unknown values survive as "unknown (raw …)". */
export function lenientEnum<const T extends readonly string[]>(values: T) {
  return z.union([z.string(), z.number()]).transform((v): T[number] | `unknown (raw ${string})` => {
    const s = String(v);
    return (values as readonly string[]).includes(s) ? (s as T[number]) : `unknown (raw ${s})`;
  });
}

/** An array whose items may be `null` holes (heaters, tools, fans, endstops). */
function holey<T extends z.ZodType>(item: T) {
  return z.array(item.nullable()).default([]);
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
  axisControls: num.optional().default(0),
  cancelButton: z.boolean().optional().default(false),
  choices: z.array(z.string()).nullable().optional().default(null),
  default: z.union([z.number(), z.string()]).nullable().optional().default(null),
  max: numOrNull,
  message: z.string().optional().default(''),
  min: numOrNull,
  mode: num,
  seq: num,
  timeout: num.optional().default(0),
  title: z.string().optional().default(''),
});
export type MessageBox = z.infer<typeof messageBoxSchema>;

const minMaxCurrent = z
  .looseObject({ current: numOrNull, min: numOrNull, max: numOrNull })
  .nullable()
  .optional()
  .default(null);

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
  active: num.optional().default(0),
  standby: num.optional().default(0),
  current: num.optional().default(-273.15),
  state: heaterState.optional().default('off'),
  max: numOrNull,
  min: numOrNull,
  sensor: num.optional().default(-1),
});
export type Heater = z.infer<typeof heaterSchema>;

export const axisSchema = z.looseObject({
  letter: z.string(),
  homed: z.boolean().optional().default(false),
  visible: z.boolean().optional().default(true),
  userPosition: numOrNull,
  machinePosition: numOrNull,
  min: numOrNull,
  max: numOrNull,
});

export const extruderSchema = z.looseObject({
  position: numOrNull,
  filament: z.string().optional().default(''),
  factor: numOrNull,
});

export const fanSchema = z.looseObject({
  name: z.string().optional().default(''),
  actualValue: numOrNull,
  requestedValue: numOrNull,
  rpm: numOrNull,
});

export const toolSchema = z.looseObject({
  number: num,
  name: z.string().optional().default(''),
  heaters: z.array(num).optional().default([]),
  active: z.array(num).optional().default([]),
  standby: z.array(num).optional().default([]),
  extruders: z.array(num).optional().default([]),
  fans: z.array(num).optional().default([]),
  state: lenientEnum(['off', 'active', 'standby'] as const)
    .optional()
    .default('off'),
});

export const volumeSchema = z.looseObject({
  path: strOrNull,
  name: strOrNull,
  mounted: z.boolean().optional().default(false),
  freeSpace: numOrNull,
  capacity: numOrNull,
});

export const thumbnailSchema = z.looseObject({
  format: lenientEnum(['png', 'jpeg', 'qoi'] as const),
  width: num.optional().default(0),
  height: num.optional().default(0),
  offset: numOrNull,
  size: numOrNull,
  /** base64, only when asked for (`readThumbnailContent=true`) or in `job.file`. */
  data: strOrNull,
});
export type Thumbnail = z.infer<typeof thumbnailSchema>;

/** ParsedFileInfo: `job.file` and `GET /machine/fileinfo/…`. When idle `job.file` has empty fields. */
export const parsedFileInfoSchema = z.looseObject({
  fileName: strOrNull,
  size: num.optional().default(0),
  lastModified: strOrNull,
  height: num.optional().default(0),
  layerHeight: num.optional().default(0),
  numLayers: num.optional().default(0),
  printTime: numOrNull,
  simulatedTime: numOrNull,
  generatedBy: strOrNull,
  filament: z.array(num).optional().default([]),
  thumbnails: z.array(thumbnailSchema).optional().default([]),
});
export type ParsedFileInfo = z.infer<typeof parsedFileInfoSchema>;

export const jobSchema = z.looseObject({
  file: parsedFileInfoSchema.nullable().optional().default(null),
  filePosition: numOrNull,
  duration: numOrNull,
  layer: numOrNull,
  layerTime: numOrNull,
  lastFileName: strOrNull,
  lastFileCancelled: z.boolean().optional().default(false),
  lastFileAborted: z.boolean().optional().default(false),
  lastFileSimulated: z.boolean().optional().default(false),
  lastDuration: numOrNull,
  pauseDuration: numOrNull,
  warmUpDuration: numOrNull,
  timesLeft: z
    .looseObject({ file: numOrNull, filament: numOrNull, slicer: numOrNull })
    .nullable()
    .optional()
    .default(null),
});

export const pluginSchema = z.looseObject({
  id: z.string().optional().default(''),
  name: z.string().optional().default(''),
  author: z.string().optional().default(''),
  version: z.string().optional().default(''),
  homepage: strOrNull,
  license: strOrNull,
  /** pid > 0: running on the SBC; -1 not running (or no SBC part). */
  pid: num.optional().default(-1),
  sbcExecutable: strOrNull,
  sbcRequired: z.boolean().optional().default(false),
});
export type Plugin = z.infer<typeof pluginSchema>;

/** `messages[]` entries: `type` 0 info (generic), 1 warning, 2 error. */
export const messageSchema = z.looseObject({
  content: z.string().optional().default(''),
  time: strOrNull,
  type: num.optional().default(0),
});
export type DuetMessage = z.infer<typeof messageSchema>;

export function messageLevel(type: number): 'info' | 'warning' | 'error' {
  return type === 2 ? 'error' : type === 1 ? 'warning' : 'info';
}

export const objectModelSchema = z.looseObject({
  boards: holey(boardSchema),
  directories: z
    .looseObject({
      filaments: z.string().optional().default('0:/filaments'),
      firmware: z.string().optional().default('0:/firmware'),
      gCodes: z.string().optional().default('0:/gcodes'),
      macros: z.string().optional().default('0:/macros'),
      menu: z.string().optional().default('0:/menu'),
      system: z.string().optional().default('0:/sys'),
      web: z.string().optional().default('0:/www'),
    })
    .optional()
    .transform(
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
  fans: holey(fanSchema),
  heat: z
    .looseObject({
      heaters: holey(heaterSchema),
      /** -1 = no heater at that index */
      bedHeaters: z.array(num).optional().default([]),
      chamberHeaters: z.array(num).optional().default([]),
    })
    .optional()
    .transform((h) => h ?? { heaters: [], bedHeaters: [], chamberHeaters: [] }),
  job: jobSchema.optional().transform((j) => j ?? jobSchema.parse({})),
  move: z
    .looseObject({
      axes: holey(axisSchema),
      extruders: holey(extruderSchema),
      compensation: z
        .looseObject({ file: strOrNull, type: z.string().optional().default('none') })
        .nullable()
        .optional()
        .default(null),
      speedFactor: numOrNull,
      kinematics: z
        .looseObject({ name: z.string().optional().default('') })
        .nullable()
        .optional()
        .default(null),
    })
    .optional()
    .transform(
      (m) => m ?? { axes: [], extruders: [], compensation: null, speedFactor: null, kinematics: null },
    ),
  network: z.looseObject({ name: strOrNull, hostname: strOrNull }).nullable().optional().default(null),
  plugins: z
    .record(z.string(), pluginSchema.nullable())
    .nullable()
    .optional()
    .transform((p) => {
      const out: Record<string, Plugin> = {};
      for (const [k, v] of Object.entries(p ?? {})) if (v) out[k] = v;
      return out;
    }),
  sbc: z
    .looseObject({ dsf: z.looseObject({ version: strOrNull }).nullable().optional().default(null) })
    .nullable()
    .optional()
    .default(null),
  state: z.looseObject({
    status: machineStatus,
    machineMode: lenientEnum(MACHINE_MODES).optional().default('FFF'),
    messageBox: messageBoxSchema.nullable().optional().default(null),
    currentTool: num.optional().default(-1),
    displayMessage: z.string().nullable().optional().default(''),
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
