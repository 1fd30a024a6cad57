/**
 * Verbatim copies of the JSON examples printed in the TouchCut manual's REST API reference
 * (../shared/protocols/touchcut-rest-api.txt). These are the only "captures" that exist: no real
 * TouchCut traffic is public (see ../shared/fixtures/touchcut/SOURCES.md). Kept as text, exactly as
 * printed, so tests see the manual's quirks.
 */

/** `curl "https://kineticcutter/rest/v1/status?units=metric"` — the manual's answer, verbatim.
 * Quirk: the text extraction turned `0.394\")` into `0.394\)`, an invalid JSON escape. */
export const MANUAL_STATUS_TEXT = String.raw`{
  "feedOverride":100,
  "materialThickness":10,
  "toolIndex":0,
  "plateOrigin":{
    "vec":[0,0,0],
    "rot":[0,0,0]
  },
  "isHomed":false,
  "plateRotation":0,
  "toolOn":false,
  "machineState":"Idle",
  "stateName":"Idle",
  "programState":"Idle",
  "toolName":"Laser Pointer",
  "commandedPos":{
    "vec":[0,0,0],
    "rot":[0,0,0]
  },
  "feedrate":0,
  "materialName":"MS",
  "heightControlAuto":true,
  "units":"metric",
  "activeCarriages":[1],
  "drossBinMode":"Disabled",
  "spacedCarriages":[1],
  "programOverride":"Idle",
  "msgStatus":[],
  "currentUser":"Operator",
  "programProgress":0,
  "programName":"No Active Program",
  "material":"MS-10.00 mm (0.394\)",
  "actualPos":{
    "vec":[0,0,0],
    "rot":[0,0,0]
  }
}`;

/** `GET rest/v1/monitor?fields=axes.axisLong,axes.axisShort&units=metric` — verbatim.
 * Quirk: `"io": []` (an empty array, not an object of groups) when no I/O was asked for. */
export const MANUAL_MONITOR_TEXT = String.raw`{
  "io": [],
  "units": "metric",
  "axes": [
    {
      "errorCode": 0,
      "canMoveRev": true,
      "canMoveFwd": true,
      "errorLimit": 1,
      "isPosErrorInputOn": false,
      "isEnabled": true,
      "torque": 0,
      "speedUnitType": "utFeed",
      "commandedPos": 0,
      "isMoving": false,
      "posError": 0,
      "index": 1,
      "isFwdSoftLimOn": false,
      "unitType": "utLength",
      "isHomeInputOn": false,
      "torqueLimit": 150,
      "io": [],
      "address": "MC, axisLong",
      "isRevLimInputOn": false,
      "scale": 1,
      "isRevSoftLimOn": false,
      "name": "axisLong",
      "isFwdLimInputOn": false,
      "actualVel": 0,
      "actualPos": 0
    },
    {
      "errorCode": 0,
      "canMoveRev": true,
      "canMoveFwd": true,
      "errorLimit": 1,
      "isPosErrorInputOn": false,
      "isEnabled": true,
      "torque": 0,
      "speedUnitType": "utFeed",
      "commandedPos": 0,
      "isMoving": false,
      "posError": 0,
      "index": 10,
      "isFwdSoftLimOn": false,
      "unitType": "utLength",
      "isHomeInputOn": false,
      "torqueLimit": 180,
      "io": [],
      "address": "MC, axisShort",
      "isRevLimInputOn": false,
      "scale": 1,
      "isRevSoftLimOn": false,
      "name": "axisShort",
      "isFwdLimInputOn": false,
      "actualVel": 0,
      "actualPos": 0
    }
  ]
}`;

/** Error bodies printed under "Failure Responses", verbatim. */
export const MANUAL_ERROR_BODIES = {
  missingUsername: '{ "code": "1003", "msg": "Required parameter missing: username" }',
  missingPassword: '{ "code": "1003", "msg": "Required parameter missing: password" }',
  notReady: '{ "code": "100", "msg": "Application not ready" }',
  invalidUsername: '{ "code": "101", "msg": "Invalid Username" }',
  invalidPassword: '{ "code": "102", "msg": "Invalid Password" }',
  jwtError: '{ "code": "2000", "msg": "Error creating JWT" }',
  jwtErrorChangePassword: '{ "code":"2000", "msg":"Error creating JWT" }',
  missingOldPassword: '{ "code": "1003", "msg": "Required parameter missing: old-password" }',
  missingNewPassword: '{ "code": "1003", "msg": "Required parameter missing: new-password" }',
  missingConfirmPassword: '{ "code": "1003", "msg": "Required parameter missing: confirm-password" }',
  confirmMismatch: '{ "code": "1002", "msg": "Invalid parameter: confirm-password" }',
} as const;

/** Success body of auth and auth/change-password, as printed (`success` is a string). */
export const MANUAL_AUTH_SUCCESS_TEXT = '{ "success": "true", "token": "<JWT>" }';

/** The API key printed in the manual's examples (a published example, not a secret). */
export const MANUAL_EXAMPLE_API_KEY = '13F513776F764DA5B5F043C93F6678381343E346C4';
