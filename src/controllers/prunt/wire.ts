import { z } from 'zod/mini';
import { addIssue } from '../../fleet/schema';

/**
 * Every payload of the Prunt web API (../shared/protocols/prunt-web-api.txt), lenient: numbers may
 * come as strings (z.coerce), unknown keys pass through, unknown kinds are kept with their raw
 * name so the form shows them as "unknown (raw …)" instead of failing.
 *
 * Two generations exist (fixtures/prunt/SOURCES.md):
 * - module API (the document): `{"Prunt config version":1,"Config":{<module>:{"Version","Config"}}}`,
 *   errors with `Path`, ticks `{"Status_Values":…,"Startup":…}`, `GET /update-check`;
 * - flat API (deployed 2025 boards): one map with `$`-joined keys, `Tabbed_Sequence`, errors with
 *   `Key`, ticks `{"Status":…}`, `GET /update_check`.
 */

/** Numbers: Ada images (" 1.17500000000000E+02") are valid JSON numbers; strings are coerced. */
const num = z.coerce.number();

/**
 * Nesting a payload may have. Prunt's deepest (a module config schema) nests about 16 levels; the
 * schemas below recurse, so a payload thousands deep would overflow the stack inside zod.
 */
export const MAX_DEPTH = 64;

/** Whether `v` nests deeper than `limit` (iterative: a payload deeper than the stack is fine). */
export function nestsDeeper(v: unknown, limit: number): boolean {
  const stack: Array<{ v: unknown; d: number }> = [{ v, d: 0 }];
  for (let item = stack.pop(); item; item = stack.pop()) {
    const x = item.v;
    if (typeof x !== 'object' || x === null) continue;
    const d = item.d + 1;
    if (d > limit) return true;
    for (const c of Object.values(x)) stack.push({ v: c, d });
  }
  return false;
}

/** A top-level payload schema: too deep a payload is refused (an issue), never parsed. */
function bounded<S extends z.ZodMiniType>(schema: S) {
  return z.pipe(
    z.unknown().check(
      z.superRefine((v, ctx) => {
        if (nestsDeeper(v, MAX_DEPTH))
          ctx.addIssue({ code: 'custom', message: `nested deeper than ${MAX_DEPTH} levels` });
      }),
    ),
    schema,
  );
}

// ---------------------------------------------------------------------------------------------
// Config schema

/** `Present_When` (newer servers): show the property only when another has one of `Values`. */
export const presentWhenSchema = z.looseObject({
  Owner: z.string(),
  Path: z.array(z.coerce.string()),
  Values: z.array(z.unknown()),
});
export type WirePresentWhen = z.infer<typeof presentWhenSchema>;

/** One property node, both generations. `Kind` is open: unknown kinds are kept as they are. */
export interface WireNode {
  Kind: string;
  Description: string;
  Children?: Record<string, WireNode>;
  Min?: number;
  Max?: number;
  Unit?: string;
  Options?: string[];
  Default?: unknown;
  Default_Numerator?: number;
  Default_Denominator?: number;
  Tabbed?: boolean;
  Experimental?: boolean;
  Present_When?: WirePresentWhen;
}

export const wireNodeSchema: z.ZodMiniType<WireNode> = z.lazy(() =>
  z.looseObject({
    Kind: z.string(),
    // The document says every node has a Description; a missing one is no reason to refuse the form.
    Description: z.catch(z.string(), ''),
    Children: z.optional(z.record(z.string(), wireNodeSchema)),
    Min: z.optional(num),
    Max: z.optional(num),
    // Flat API writes Unit with Unbounded_String'Image: a quoted string that arrives as a plain string.
    Unit: z.optional(z.string()),
    Options: z.optional(z.array(z.coerce.string())),
    Default: z.optional(z.unknown()),
    Default_Numerator: z.optional(num),
    Default_Denominator: z.optional(num),
    Tabbed: z.optional(z.boolean()),
    Experimental: z.optional(z.boolean()),
    Present_When: z.optional(presentWhenSchema),
  }),
);

export const moduleSchemaSchema = z.looseObject({
  'Prunt config version': num,
  Config: z.record(
    z.string(),
    z.looseObject({
      Version: num,
      Config: z.record(z.string(), wireNodeSchema),
    }),
  ),
});
export type ModuleConfigSchema = z.infer<typeof moduleSchemaSchema>;

export const flatSchemaSchema = z.record(z.string(), wireNodeSchema);
export type FlatConfigSchema = z.infer<typeof flatSchemaSchema>;

export type ConfigSchemaWire =
  { api: 'module'; schema: ModuleConfigSchema } | { api: 'flat'; schema: FlatConfigSchema };

/** `GET /config/schema`: the generation is detected from the shape. */
export const configSchemaSchema = z.pipe(
  z.unknown(),
  z.transform((v, ctx): ConfigSchemaWire => {
    if (nestsDeeper(v, MAX_DEPTH)) {
      addIssue(ctx, { code: 'custom', message: `nested deeper than ${MAX_DEPTH} levels` });
      return z.NEVER;
    }
    if (v && typeof v === 'object' && !Array.isArray(v) && 'Prunt config version' in v) {
      const r = moduleSchemaSchema.safeParse(v);
      if (r.success) return { api: 'module', schema: r.data };
      for (const i of r.error.issues)
        addIssue(ctx, { ...i, code: 'custom', message: i.message, path: i.path });
      return z.NEVER;
    }
    const r = flatSchemaSchema.safeParse(v);
    if (r.success) return { api: 'flat', schema: r.data };
    for (const i of r.error.issues) addIssue(ctx, { code: 'custom', message: i.message, path: i.path });
    return z.NEVER;
  }),
);

// ---------------------------------------------------------------------------------------------
// Config values

/** A leaf value as sent: flat API values are booleans, numbers (ints or Ada E-format), strings. */
export const flatValueSchema = z.union([z.boolean(), z.number(), z.string()]);

/**
 * Errors: module API `{"Path":[…],"Message"}`, flat API `{"Key","Message"}`. Either may be
 * missing; an error we cannot place is still shown (above the form).
 */
export const configErrorSchema = z.looseObject({
  Key: z.optional(z.string()),
  Path: z.optional(z.array(z.coerce.string())),
  Message: z.catch(z.coerce.string(), '(no message)'),
});
export type ConfigErrorWire = z.infer<typeof configErrorSchema>;

/** `GET /config/values` and the 200 reply to `POST /config/values` (which may still be a rejection). */
export const configValuesSchema = bounded(
  z.looseObject({
    Values: z.record(z.string(), z.unknown()),
    Errors: z._default(z.catch(z.array(configErrorSchema), []), []),
  }),
);
export type ConfigValuesWire = z.infer<typeof configValuesSchema>;

export const moduleValuesSchema = z.looseObject({
  'Prunt config version': num,
  Config: z.record(z.string(), z.looseObject({ Version: num, Config: z.record(z.string(), z.unknown()) })),
});

// ---------------------------------------------------------------------------------------------
// Status

export const STATUS_KINDS = ['Real', 'Integer', 'Boolean', 'String'] as const;

/** Module API status schema node; an unknown Kind maps to "unknown (raw …)". */
export const statusNodeSchema = z.looseObject({
  Kind: z.catch(
    z.pipe(
      z.string(),
      z.transform((k) => ((STATUS_KINDS as readonly string[]).includes(k) ? k : `unknown (raw ${k})`)),
    ),
    'unknown (raw missing)',
  ),
  Unit: z.catch(z.string(), ''),
  Description: z.catch(z.string(), ''),
  Condition: z.catch(z.string(), ''),
});

export const moduleStatusSchemaSchema = z.record(
  z.string(),
  z.record(z.string(), z.record(z.string(), statusNodeSchema)),
);
/** Flat API: `{"Position":["X_AXIS",…],…}` (group → names). */
export const flatStatusSchemaSchema = z.record(z.string(), z.array(z.coerce.string()));

export type StatusSchemaWire =
  | { api: 'module'; schema: z.infer<typeof moduleStatusSchemaSchema> }
  | { api: 'flat'; schema: z.infer<typeof flatStatusSchemaSchema> };

export const statusSchemaSchema = z.pipe(
  z.unknown(),
  z.transform((v, ctx): StatusSchemaWire => {
    if (nestsDeeper(v, MAX_DEPTH)) {
      addIssue(ctx, { code: 'custom', message: `nested deeper than ${MAX_DEPTH} levels` });
      return z.NEVER;
    }
    const flat = flatStatusSchemaSchema.safeParse(v);
    if (flat.success) return { api: 'flat', schema: flat.data };
    const mod = moduleStatusSchemaSchema.safeParse(v);
    if (mod.success) return { api: 'module', schema: mod.data };
    for (const i of mod.error.issues) addIssue(ctx, { code: 'custom', message: i.message, path: i.path });
    return z.NEVER;
  }),
);

export const statusScalarSchema = z.union([z.number(), z.boolean(), z.string(), z.null()]);

/** Module API status values: module → group → name → value. */
export const moduleStatusValuesSchema = z.record(
  z.string(),
  z.record(z.string(), z.record(z.string(), z.catch(statusScalarSchema, null))),
);
export type ModuleStatusValues = z.infer<typeof moduleStatusValuesSchema>;

/** Flat API status (inside `{"Status":…}`): groups of values plus scalars (Time, Startup, …). */
export const flatStatusSchema = z.record(
  z.string(),
  z.union([statusScalarSchema, z.record(z.string(), z.catch(statusScalarSchema, null))]),
);
export type FlatStatusValues = z.infer<typeof flatStatusSchema>;

/** `GET /status/values`: flat API wraps it in `{"Status":…}`. */
export const statusValuesSchema = z.pipe(
  z.unknown(),
  z.transform((v, ctx) => {
    if (nestsDeeper(v, MAX_DEPTH)) {
      addIssue(ctx, { code: 'custom', message: `nested deeper than ${MAX_DEPTH} levels` });
      return z.NEVER;
    }
    if (v && typeof v === 'object' && 'Status' in v) {
      const r = flatStatusSchema.safeParse((v as { Status: unknown }).Status);
      if (r.success) return { api: 'flat' as const, values: r.data };
      for (const i of r.error.issues)
        addIssue(ctx, { code: 'custom', message: i.message, path: ['Status', ...i.path] });
      return z.NEVER;
    }
    const r = moduleStatusValuesSchema.safeParse(v);
    if (r.success) return { api: 'module' as const, values: r.data };
    for (const i of r.error.issues) addIssue(ctx, { code: 'custom', message: i.message, path: i.path });
    return z.NEVER;
  }),
);

export const STARTUP_STATES = ['Done', 'Update_Running', 'Update_Required', 'Waiting'] as const;
export type StartupState = (typeof STARTUP_STATES)[number] | `unknown (raw ${string})`;

export const startupSchema = z.pipe(
  z.string(),
  z.transform((s): StartupState =>
    (STARTUP_STATES as readonly string[]).includes(s) ? (s as StartupState) : `unknown (raw ${s})`,
  ),
);

// ---------------------------------------------------------------------------------------------
// WebSocket /websocket/everything

export const smartPlugSchema = z.looseObject({
  Enabled: z.catch(z.boolean(), false),
  Host: z.catch(z.string(), ''),
  Provider: z.catch(z.string(), ''),
  Power: z.catch(z.string(), 'UNKNOWN'),
  Watchdog_Active: z.catch(z.boolean(), false),
  Watchdog_Seconds: z.catch(num, 0),
  Busy: z.catch(z.boolean(), false),
  Error: z.catch(z.string(), ''),
});
export type SmartPlug = z.infer<typeof smartPlugSchema>;

export const GCODE_KINDS = ['Running', 'Output', 'Completed', 'Cancelled', 'Failed'] as const;

export type WsMessage =
  | { type: 'start'; startTime: string }
  | {
      type: 'tick';
      api: 'module';
      values: ModuleStatusValues;
      startup: StartupState | null;
      smartPlug: SmartPlug | null;
      exception: { message: string; fatal: boolean } | null;
    }
  | { type: 'tick'; api: 'flat'; values: FlatStatusValues; startup: StartupState | null }
  | { type: 'log'; text: string }
  | { type: 'gcode'; id: string; kind: string; message: string | null }
  | { type: 'unknown'; keys: string[] };

const wsObject = z.looseObject({
  Server_Start_Time: z.optional(z.coerce.string()),
  Status_Values: z.optional(moduleStatusValuesSchema),
  Status: z.optional(flatStatusSchema),
  Startup: z.optional(startupSchema),
  Smart_Plug: z.optional(z.nullable(smartPlugSchema)),
  Server_Exception: z.optional(
    z.nullable(z.looseObject({ Message: z.catch(z.coerce.string(), ''), Fatal: z.catch(z.boolean(), true) })),
  ),
  Log: z.optional(z.coerce.string()),
  Gcode_Command: z.optional(
    z.looseObject({
      ID: z.coerce.string(),
      Kind: z.pipe(
        z.string(),
        z.transform((k) => ((GCODE_KINDS as readonly string[]).includes(k) ? k : `unknown (raw ${k})`)),
      ),
      Message: z.optional(z.coerce.string()),
    }),
  ),
});

/** One WebSocket frame → a message, or a zod error (the caller logs it as a protocol problem). */
export const wsMessageSchema = z.pipe(
  bounded(wsObject),
  z.transform((m): WsMessage => {
    if (m.Server_Start_Time !== undefined) return { type: 'start', startTime: m.Server_Start_Time.trim() };
    if (m.Status_Values !== undefined) {
      return {
        type: 'tick',
        api: 'module',
        values: m.Status_Values,
        startup: m.Startup ?? null,
        smartPlug: m.Smart_Plug ?? null,
        exception: m.Server_Exception
          ? { message: m.Server_Exception.Message, fatal: m.Server_Exception.Fatal }
          : null,
      };
    }
    if (m.Status !== undefined) {
      const st = m.Status['Startup'];
      const startup = typeof st === 'string' ? startupSchema.parse(st) : (m.Startup ?? null);
      return { type: 'tick', api: 'flat', values: m.Status, startup };
    }
    if (m.Log !== undefined) return { type: 'log', text: m.Log };
    if (m.Gcode_Command) {
      return {
        type: 'gcode',
        id: m.Gcode_Command.ID,
        kind: m.Gcode_Command.Kind,
        message: m.Gcode_Command.Message ?? null,
      };
    }
    return { type: 'unknown', keys: Object.keys(m) };
  }),
);

// ---------------------------------------------------------------------------------------------
// Files, update check, commands

/** `GET /uploads/`: a JSON array of file names. */
export const uploadsSchema = z.array(z.coerce.string());

/** `GET /update-check` (module) / `GET /update_check` (flat): `{"Available","URL"}`. */
export const updateCheckSchema = z.looseObject({
  Available: z.catch(z.boolean(), false),
  URL: z.catch(z.string(), ''),
});
export type UpdateCheck = z.infer<typeof updateCheckSchema>;

/** Newer servers answer `POST /run-command` with `{"ID":"…"}`; older ones with 204 and no body. */
export const runCommandReplySchema = z.looseObject({ ID: z.coerce.string() });
