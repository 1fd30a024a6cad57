/**
 * The g2core configuration keys' human names and descriptions, one table per group kind (the
 * lookups and parsing that use them: settings-meta.ts). One data table: long, but one thing.
 */

export type FieldKind = 'number' | 'integer' | 'boolean' | 'flag' | 'enum' | 'text';

export interface KeyMeta {
  name: string;
  description: string;
  kind: FieldKind;
  unit?: string;
  options?: Record<number, string>;
  readOnly?: boolean;
  min?: number;
  max?: number;
}

export type GroupKind = 'sys' | 'axis' | 'motor' | 'do' | 'di' | 'heater' | 'offset' | 'other';

const ON_OFF: Record<number, string> = { 0: 'off', 1: 'on' };

const SYS: Record<string, KeyMeta> = {
  fb: { name: 'Firmware build', description: 'Build number of the firmware.', kind: 'text', readOnly: true },
  fbs: {
    name: 'Build string',
    description: 'git describe of the firmware build.',
    kind: 'text',
    readOnly: true,
  },
  fbc: {
    name: 'Settings file',
    description: 'Settings file the firmware was built with.',
    kind: 'text',
    readOnly: true,
  },
  fv: { name: 'Firmware version', description: 'Firmware version.', kind: 'text', readOnly: true },
  hp: { name: 'Hardware platform', description: 'Board family.', kind: 'text', readOnly: true },
  hv: { name: 'Hardware version', description: 'Board revision.', kind: 'text', readOnly: true },
  id: { name: 'Board id', description: 'Unique id of the board.', kind: 'text', readOnly: true },
  jt: {
    name: 'Junction integration time',
    description: 'Cornering speed factor: higher is faster through corners, lower is more precise.',
    kind: 'number',
  },
  ct: {
    name: 'Chordal tolerance',
    description: 'Maximum deviation of arc segments from the true arc.',
    kind: 'number',
    unit: 'mm',
  },
  sl: {
    name: 'Soft limits',
    description: 'Refuse moves outside each axis travel min/max once the axis is homed.',
    kind: 'flag',
    options: ON_OFF,
  },
  lim: {
    name: 'Hard limits',
    description: 'Limit switches stop the machine (ALARM) when hit.',
    kind: 'flag',
    options: ON_OFF,
  },
  saf: {
    name: 'Safety interlock',
    description: 'Honour the safety interlock input (holds motion when open).',
    kind: 'flag',
    options: ON_OFF,
  },
  m48e: {
    name: 'M48 override enable',
    description: 'Whether M48/M49 may enable and disable the overrides.',
    kind: 'flag',
    options: ON_OFF,
  },
  mfoe: {
    name: 'Feed override enable',
    description: 'Apply the manual feed override factor (mfo).',
    kind: 'flag',
    options: ON_OFF,
  },
  mfo: {
    name: 'Feed override',
    description: 'Feed rate override factor (0.05 – 2.0).',
    kind: 'number',
    min: 0.05,
    max: 2,
  },
  mtoe: {
    name: 'Traverse override enable',
    description: 'Apply the traverse (rapid) override factor (mto).',
    kind: 'flag',
    options: ON_OFF,
  },
  mto: {
    name: 'Traverse override',
    description: 'Rapid traverse override factor (0.05 – 1.0).',
    kind: 'number',
    min: 0.05,
    max: 2,
  },
  mt: {
    name: 'Motor timeout',
    description: 'Seconds motors stay powered after motion stops.',
    kind: 'number',
    unit: 's',
  },
  spep: {
    name: 'Spindle enable polarity',
    description: 'Electrical level that turns the spindle on.',
    kind: 'enum',
    options: { 0: 'active low', 1: 'active high' },
  },
  spdp: {
    name: 'Spindle direction polarity',
    description: 'Electrical level for clockwise rotation.',
    kind: 'enum',
    options: { 0: 'CW low', 1: 'CW high' },
  },
  spph: {
    name: 'Spindle pause on hold',
    description: 'Stop the spindle during a feedhold.',
    kind: 'flag',
    options: ON_OFF,
  },
  spdw: {
    name: 'Spindle dwell',
    description: 'Seconds to wait after the spindle starts.',
    kind: 'number',
    unit: 's',
  },
  ssoe: {
    name: 'Spindle override enable',
    description: 'Apply the spindle speed override factor (sso).',
    kind: 'flag',
    options: ON_OFF,
  },
  sso: {
    name: 'Spindle override',
    description: 'Spindle speed override factor (0.05 – 2.0).',
    kind: 'number',
    min: 0.05,
    max: 2,
  },
  cofp: {
    name: 'Flood coolant polarity',
    description: 'Electrical level that turns flood coolant on.',
    kind: 'enum',
    options: { 0: 'active low', 1: 'active high' },
  },
  comp: {
    name: 'Mist coolant polarity',
    description: 'Electrical level that turns mist coolant on.',
    kind: 'enum',
    options: { 0: 'active low', 1: 'active high' },
  },
  coph: {
    name: 'Coolant pause on hold',
    description: 'Stop coolant during a feedhold.',
    kind: 'flag',
    options: ON_OFF,
  },
  tv: {
    name: 'Text verbosity',
    description: 'Text-mode response verbosity.',
    kind: 'enum',
    options: { 0: 'silent', 1: 'verbose' },
  },
  ej: {
    name: 'JSON mode',
    description: 'Communications mode at startup.',
    kind: 'enum',
    options: { 0: 'text', 1: 'JSON' },
  },
  jv: {
    name: 'JSON verbosity',
    description: 'How much each JSON response contains.',
    kind: 'enum',
    options: { 0: 'silent', 1: 'footer', 2: 'messages', 3: 'configs', 4: 'line numbers', 5: 'verbose' },
  },
  qv: {
    name: 'Queue reports',
    description: 'Planner queue report verbosity.',
    kind: 'enum',
    options: { 0: 'off', 1: 'single', 2: 'triple' },
  },
  sv: {
    name: 'Status reports',
    description: 'Status report verbosity.',
    kind: 'enum',
    options: { 0: 'off', 1: 'filtered', 2: 'verbose' },
  },
  si: {
    name: 'Status interval',
    description: 'Milliseconds between status reports (minimum 100).',
    kind: 'integer',
    unit: 'ms',
    min: 100,
  },
  gpl: {
    name: 'Default plane',
    description: 'Plane selected at power-up and program end.',
    kind: 'enum',
    options: { 0: 'G17 XY', 1: 'G18 XZ', 2: 'G19 YZ' },
  },
  gun: {
    name: 'Default units',
    description: 'Units at power-up and program end.',
    kind: 'enum',
    options: { 0: 'G20 inches', 1: 'G21 millimeters' },
  },
  gco: {
    name: 'Default coordinate system',
    description: 'Work coordinate system at power-up.',
    kind: 'enum',
    options: { 1: 'G54', 2: 'G55', 3: 'G56', 4: 'G57', 5: 'G58', 6: 'G59' },
  },
  gpa: {
    name: 'Default path control',
    description: 'Path control mode at power-up.',
    kind: 'enum',
    options: { 0: 'G61 exact path', 1: 'G61.1 exact stop', 2: 'G64 continuous' },
  },
  gdi: {
    name: 'Default distance mode',
    description: 'Distance mode at power-up.',
    kind: 'enum',
    options: { 0: 'G90 absolute', 1: 'G91 incremental' },
  },
};

const AXIS: Record<string, KeyMeta> = {
  am: {
    name: 'Axis mode',
    description: 'How the axis takes part in motion.',
    kind: 'enum',
    options: { 0: 'disabled', 1: 'standard', 2: 'inhibited', 3: 'radius' },
  },
  vm: {
    name: 'Max velocity',
    description: 'Maximum speed of rapid (G0) moves.',
    kind: 'number',
    unit: 'mm/min',
    min: 0,
  },
  fr: {
    name: 'Max feed rate',
    description: 'Maximum feed rate for G1/G2/G3 moves.',
    kind: 'number',
    unit: 'mm/min',
    min: 0,
  },
  tn: {
    name: 'Travel min',
    description: 'Lowest position (soft limit and homing target when searching toward min).',
    kind: 'number',
    unit: 'mm',
  },
  tm: {
    name: 'Travel max',
    description: 'Highest position (soft limit and homing target when searching toward max).',
    kind: 'number',
    unit: 'mm',
  },
  jm: { name: 'Max jerk', description: 'Maximum jerk in millions of mm/min³.', kind: 'number', min: 0 },
  jh: {
    name: 'Homing jerk',
    description: 'Jerk used while homing (stops quickly at the switch).',
    kind: 'number',
    min: 0,
  },
  jd: { name: 'Junction deviation', description: 'Cornering deviation (older builds).', kind: 'number' },
  ra: {
    name: 'Radius',
    description: 'Radius used to convert linear to rotary units in radius mode.',
    kind: 'number',
    unit: 'mm',
  },
  hi: {
    name: 'Homing input',
    description: 'Digital input of the homing switch (0: axis is not homed).',
    kind: 'integer',
    min: 0,
    max: 9,
  },
  hd: {
    name: 'Homing direction',
    description: 'Which way the homing search moves.',
    kind: 'enum',
    options: { 0: 'toward min', 1: 'toward max' },
  },
  sv: {
    name: 'Search velocity',
    description: 'Speed while searching for the homing switch.',
    kind: 'number',
    unit: 'mm/min',
    min: 0,
  },
  lv: {
    name: 'Latch velocity',
    description: 'Slow speed while latching off the switch.',
    kind: 'number',
    unit: 'mm/min',
    min: 0,
  },
  lb: {
    name: 'Latch backoff',
    description: 'Distance to back off the switch before latching.',
    kind: 'number',
    unit: 'mm',
  },
  zb: {
    name: 'Zero backoff',
    description: 'Distance from the switch to the axis zero after homing.',
    kind: 'number',
    unit: 'mm',
  },
};

const MOTOR: Record<string, KeyMeta> = {
  ma: {
    name: 'Motor map',
    description: 'Axis this motor drives.',
    kind: 'enum',
    options: { 0: 'X', 1: 'Y', 2: 'Z', 3: 'A', 4: 'B', 5: 'C' },
  },
  sa: {
    name: 'Step angle',
    description: 'Degrees per full step of the motor (1.8 or 0.9 usually).',
    kind: 'number',
    unit: '°',
  },
  tr: {
    name: 'Travel per revolution',
    description: 'Distance (or degrees) the axis moves per motor revolution.',
    kind: 'number',
    unit: 'mm',
  },
  mi: {
    name: 'Microsteps',
    description: 'Microstep setting of the driver.',
    kind: 'enum',
    options: { 1: '1', 2: '2', 4: '4', 8: '8', 16: '16', 32: '32', 64: '64', 128: '128', 256: '256' },
  },
  su: {
    name: 'Steps per unit',
    description: 'Derived from step angle, travel per revolution and microsteps.',
    kind: 'number',
  },
  po: {
    name: 'Polarity',
    description: 'Direction of rotation.',
    kind: 'enum',
    options: { 0: 'normal', 1: 'reversed' },
  },
  ep: {
    name: 'Enable polarity',
    description: 'Electrical level of the driver enable line.',
    kind: 'enum',
    options: { 0: 'active high', 1: 'active low' },
  },
  pm: {
    name: 'Power mode',
    description: 'When the motor is energized.',
    kind: 'enum',
    options: { 0: 'disabled', 1: 'always on', 2: 'on in cycle', 3: 'on when moving' },
  },
  pl: {
    name: 'Power level',
    description: 'Motor current as a fraction of the maximum (0 – 1).',
    kind: 'number',
    min: 0,
    max: 1,
  },
};

const DOUT: Record<string, KeyMeta> = {
  mo: {
    name: 'Output mode',
    description: 'Electrical sense of the output.',
    kind: 'enum',
    options: { 0: 'active low', 1: 'active high', [-1]: 'disabled' },
  },
};

const DIN: Record<string, KeyMeta> = {
  mo: {
    name: 'Input mode',
    description: 'Electrical sense of the switch.',
    kind: 'enum',
    options: { 0: 'active low (NO)', 1: 'active high (NC)', [-1]: 'disabled' },
  },
  ac: {
    name: 'Action',
    description: 'What the machine does when the input triggers.',
    kind: 'enum',
    options: { 0: 'none', 1: 'stop', 2: 'fast stop', 3: 'halt', 4: 'panic', 5: 'reset' },
  },
  fn: {
    name: 'Function',
    description: 'What the input is used for.',
    kind: 'enum',
    options: { 0: 'none', 1: 'limit', 2: 'interlock', 3: 'shutdown', 4: 'probe' },
  },
};

const HEATER: Record<string, KeyMeta> = {
  e: { name: 'Enabled', description: 'Heater control on.', kind: 'boolean' },
  p: { name: 'PID P', description: 'Proportional gain.', kind: 'number' },
  i: { name: 'PID I', description: 'Integral gain.', kind: 'number' },
  d: { name: 'PID D', description: 'Derivative gain.', kind: 'number' },
  st: { name: 'Set temperature', description: 'Target temperature.', kind: 'number', unit: '°C' },
  t: {
    name: 'Temperature',
    description: 'Measured temperature (-1: no sensor).',
    kind: 'number',
    unit: '°C',
    readOnly: true,
  },
  op: { name: 'Output', description: 'Current heater output (0 – 1).', kind: 'number', readOnly: true },
  tr: {
    name: 'Thermistor resistance',
    description: 'Measured sensor resistance.',
    kind: 'number',
    unit: 'Ω',
    readOnly: true,
  },
  at: { name: 'At target', description: 'Temperature is at the set point.', kind: 'boolean', readOnly: true },
  an: {
    name: 'ADC reading',
    description: 'Raw analog reading of the sensor.',
    kind: 'number',
    readOnly: true,
  },
  fp: {
    name: 'Fan PWM',
    description: 'Fan power when the heater is above the fan threshold.',
    kind: 'number',
  },
  fm: { name: 'Fan minimum', description: 'Lowest fan power.', kind: 'number' },
  fl: {
    name: 'Fan low temperature',
    description: 'Temperature at which the fan starts.',
    kind: 'number',
    unit: '°C',
  },
  fh: {
    name: 'Fan high temperature',
    description: 'Temperature at which the fan is at full power.',
    kind: 'number',
    unit: '°C',
  },
};

const OFFSET: Record<string, KeyMeta> = Object.fromEntries(
  ['x', 'y', 'z', 'a', 'b', 'c'].map((a) => [
    a,
    {
      name: `${a.toUpperCase()} offset`,
      description: `Offset of the ${a.toUpperCase()} axis.`,
      kind: 'number' as const,
      unit: 'xyz'.includes(a) ? 'mm' : '°',
    },
  ]),
);

export const TABLES: Record<GroupKind, Record<string, KeyMeta>> = {
  sys: SYS,
  axis: AXIS,
  motor: MOTOR,
  do: DOUT,
  di: DIN,
  heater: HEATER,
  offset: OFFSET,
  other: {},
};
