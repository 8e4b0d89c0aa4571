// The questionnaire step of the station: the questionnaire the server's state names (phase
// "questionnaire"), one row of scale points per item; the answers go as one `answers` message once
// every item has one. station.js calls renderQuestionnaire(state.questionnaire, send).
"use strict";

function renderQuestionnaire(questionnaire, send) {
  const form = document.getElementById("questionnaire-form");
  if (form.dataset.shown === `${questionnaire.name}/${questionnaire.placement}/${questionnaire.trial}`) return;
  form.dataset.shown = `${questionnaire.name}/${questionnaire.placement}/${questionnaire.trial}`;
  document.getElementById("questionnaire-title").textContent = questionnaire.title;
  document.getElementById("questionnaire-instructions").textContent = questionnaire.instructions;
  form.replaceChildren();
  const { min, max, step } = questionnaire.scale;
  const points = [];
  for (let value = min; value <= max + 1e-9; value += step) points.push(Math.round(value * 1000) / 1000);
  const answers = {};
  const submit = document.createElement("button");
  submit.type = "submit";
  submit.id = "questionnaire-submit";
  submit.textContent = "Submit";
  submit.disabled = true;
  questionnaire.items.forEach((item, index) => {
    const row = document.createElement("fieldset");
    row.className = "item";
    const legend = document.createElement("legend");
    legend.textContent = `${index + 1}. ${item.text}`;
    row.appendChild(legend);
    const low = document.createElement("span");
    low.className = "anchor";
    low.textContent = item.low || questionnaire.scale.low;
    row.appendChild(low);
    for (const value of points) {
      const label = document.createElement("label");
      const input = document.createElement("input");
      input.type = "radio";
      input.name = item.id;
      input.value = String(value);
      input.addEventListener("change", () => {
        answers[item.id] = value;
        submit.disabled = Object.keys(answers).length !== questionnaire.items.length;
      });
      label.appendChild(input);
      label.appendChild(document.createTextNode(String(value)));
      row.appendChild(label);
    }
    const high = document.createElement("span");
    high.className = "anchor";
    high.textContent = item.high || questionnaire.scale.high;
    row.appendChild(high);
    form.appendChild(row);
  });
  form.appendChild(submit);
  form.onsubmit = (event) => {
    event.preventDefault();
    submit.disabled = true;
    send({ type: "answers", questionnaire: questionnaire.name, answers });
  };
}
